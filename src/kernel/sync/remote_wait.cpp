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

namespace {

std::uint32_t task_id(const Tcb* t) { return std::uint32_t(tid_of(t)) + 1; }

// Priorities in an unsigned order. 0 stays free for "the lowest" (what
// the deadline policies publish) and UINT32_MAX for "interrupt whatever
// runs" (their waiters, and vectors with handlers).
std::uint32_t fixed_urgency(int priority) {
    const std::uint32_t u = std::uint32_t(priority) ^ 0x80000000u;
    return u == 0 ? 1 : u == UINT32_MAX ? UINT32_MAX - 1 : u;
}

bool priority_is_the_order() { return g_k.builtin && g_k.policy == CHM_SCHED_FIXED; }

}  // namespace

std::uint32_t remote_waiter_id() { return remote_wait_possible() ? task_id(g_k.current) : 0; }

std::uint32_t remote_waiter_urgency() {
    if (!priority_is_the_order()) return UINT32_MAX;
    const Tcb* cur = port::on_kernel_thread() ? g_k.current : nullptr;
    return cur ? fixed_urgency(cur->s.priority) : UINT32_MAX;
}

void publish_running_locked() {
    const Tcb* t = g_k.current;
    if (!t) return port::doorbell_publish_locked(0, 0);
    port::doorbell_publish_locked(task_id(t), priority_is_the_order() ? fixed_urgency(t->s.priority) : 0);
}

void remote_scan_locked() {
    Tcb* t = g_remote.head;
    while (t) {
        Tcb* next = t->wnext;
        if (word_granted(__atomic_load_n(t->rword, __ATOMIC_ACQUIRE))) wake_locked(t, 0);
        t = next;
    }
}

bool remote_waiting_locked() { return g_remote.head != nullptr; }

namespace {

// Move every parked task's word from `from` to `to` where it still holds
// `from`; true when one holds a grant instead. Granters exchange the word,
// so each either finds the mark (and leaves the wake-up to the poll) or
// comes after the unmarking and rings.
bool move_words(std::uint32_t from, std::uint32_t to) {
    bool granted = false;
    for (const Tcb* t = g_remote.head; t; t = t->wnext) {
        std::uint32_t expect = from;
        if (!__atomic_compare_exchange_n(t->rword, &expect, to, false, __ATOMIC_ACQ_REL, __ATOMIC_ACQUIRE))
            granted |= word_granted(expect);
    }
    return granted;
}

// Mark the words watched before the poll; unmark them after it.
bool watch_begin() { return move_words(0, kWordWatched); }
bool watch_end() { return move_words(kWordWatched, 0); }

bool watch_woken() {
    for (const Tcb* t = g_remote.head; t; t = t->wnext)
        if (word_granted(__atomic_load_n(t->rword, __ATOMIC_ACQUIRE))) return true;
    return false;
}

}  // namespace

const port::IdleWatch kRemoteWatch{watch_begin, watch_woken, watch_end};

void remote_scan() {
    IrqGuard guard;
    remote_scan_locked();
    reschedule_locked();
}

int remote_wait(std::uint32_t* word, std::int64_t timeout_ns) {
    if (!remote_wait_possible()) return -EPERM;
    IrqGuard guard;
    // Set before we parked: no need to wait (the ring may already be spent).
    if (word_granted(__atomic_load_n(word, __ATOMIC_ACQUIRE))) return 0;
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
