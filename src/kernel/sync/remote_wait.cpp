// Tasks parked on shared-memory words (sync/remote_wait.hpp). The waiters
// of all words are one list: a grant rings the RTPU once and the handler
// scans it (a handful of remote waits per RTPU, so a scan beats an index).
#include <cerrno>

#include "kernel.hpp"
#include "sync/remote_wait.hpp"

namespace chm::kernel {

namespace {
WaitQueue g_remote;  // tasks parked in remote_wait, most urgent first
}

bool remote_wait_possible() {
    if (!port::on_kernel_thread() || g_k.in_irq) return false;
    const Tcb* cur = g_k.current;
    return cur && !cur->lock_nest;
}

int remote_waiter_priority() {
    const Tcb* cur = port::on_kernel_thread() ? g_k.current : nullptr;
    return cur ? cur->s.priority : 0;
}

void remote_scan_locked() {
    Tcb* t = g_remote.head;
    while (t) {
        Tcb* next = t->wnext;
        if (__atomic_load_n(t->rword, __ATOMIC_ACQUIRE) != 0) wake_locked(t, 0);
        t = next;
    }
}

void remote_scan() {
    IrqGuard guard;
    remote_scan_locked();
    reschedule_locked();
}

int remote_wait(const std::uint32_t* word, std::int64_t timeout_ns) {
    if (!remote_wait_possible()) return -EPERM;
    IrqGuard guard;
    // Set before we parked: no need to wait (the ring may already be spent).
    if (__atomic_load_n(word, __ATOMIC_ACQUIRE) != 0) return 0;
    if (timeout_ns == 0) return -ETIMEDOUT;
    Tcb* cur = g_k.current;
    cur->rword = word;
    cur->state = TaskState::Blocked;
    cur->interruptible = true;
    cur->wait_result = 0;
    waitq_insert_locked(&g_remote, cur);
    const std::uint64_t now = now_locked();
    if (timeout_ns > 0) {
        cur->tmr.kind = TimerKind::Wake;
        timer_add_locked(&cur->tmr, now + std::uint64_t(timeout_ns));
        timer_program_locked(now);
    }
    // A grant between the test above and here rang the doorbell: its
    // dispatch runs before any other task and finds us in the list.
    const int r = block_current_locked();
    cur->rword = nullptr;
    deliver_pending_locked();
    return r;
}

}  // namespace chm::kernel
