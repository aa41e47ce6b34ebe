// Wait queues: tasks blocked on one object, most urgent first. Insertion
// walks the queue (waiters of one object are few); wake-up takes the head.
#include <cerrno>

#include "kernel.hpp"

namespace chm::kernel {

void waitq_insert_locked(WaitQueue* q, Tcb* t) {
    const std::uint64_t now = now_cached_locked();
    Tcb** link = &q->head;
    // Behind every waiter at least as urgent: FIFO among equals.
    while (*link && !sched_before_locked(t, *link, now)) link = &(*link)->wnext;
    t->wnext = *link;
    *link = t;
    t->wq = q;
}

void waitq_unlink_locked(Tcb* t) {
    WaitQueue* q = t->wq;
    for (Tcb** link = &q->head; *link; link = &(*link)->wnext) {
        if (*link == t) {
            *link = t->wnext;
            break;
        }
    }
    t->wnext = nullptr;
    t->wq = nullptr;
}

void wake_locked(Tcb* t, int result) {
    waitq_remove_locked(t);
    timer_cancel_locked(&t->tmr);
    t->wait_result = result;
    t->interruptible = false;
    make_ready_locked(t);
}

}  // namespace chm::kernel
