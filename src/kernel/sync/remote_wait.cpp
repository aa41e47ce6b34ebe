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

// Move `word` from `from` to `to`; true when it holds a grant instead.
bool move_word(std::uint32_t* word, std::uint32_t from, std::uint32_t to) {
    return !__atomic_compare_exchange_n(word, &from, to, false, __ATOMIC_ACQ_REL, __ATOMIC_ACQUIRE) &&
           word_granted(from);
}

// Move every parked task's word from `from` to `to` where it still holds
// `from`; true when one holds a grant instead. Granters exchange the word,
// so each either finds the mark (and leaves the wake-up to the poll) or
// comes after the unmarking and rings.
bool move_words(std::uint32_t from, std::uint32_t to) {
    bool granted = false;
    for (const Tcb* t = g_remote.head; t; t = t->wnext) granted |= move_word(t->rword, from, to);
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

namespace {

// True while the RTPU has nothing to do but wait with the calling task: no
// other task ready, no vector or tick pending, no signal or deadline miss
// for the caller. Mask held.
bool only_waiting_locked() {
    const Tcb* cur = g_k.current;
    if (port::g_irq.pending || port::doorbell_raised()) return false;
    if ((cur->sig_pending & ~cur->sig_blocked) || cur->miss_pending) return false;
    return !sched_pick_locked(now_cached_locked());
}

// How long the caller may spin before it parks (0: not at all): the idle
// poll, when the RTPU polls and has nothing else to do. Mask held.
std::uint64_t spin_limit_locked(std::int64_t timeout_ns) {
    const std::uint64_t poll = g_k.cfg.idle_poll_ns;
    if (!poll || timeout_ns == 0 || g_k.cfg.virtual_clock || io_watching_locked()) return 0;
    if (!only_waiting_locked()) return 0;
    return timeout_ns > 0 && std::uint64_t(timeout_ns) < poll ? std::uint64_t(timeout_ns) : poll;
}

// How a spin ended: granted, something else to run (or a tick or vector
// pending), idle_poll_ns spent, or a user signal.
enum class Spun { kGranted, kOver, kSpent, kSignalled };

// A user signal since the wait began (`taken`: the caller's sigs_taken
// then): pending, or handled already at a preemption's return. Mask held.
bool signalled_locked(std::uint32_t taken) {
    const Tcb* cur = g_k.current;
    return (cur->sig_pending & ~cur->sig_blocked) || cur->sigs_taken != taken;
}

// Before it parks, a task whose RTPU would otherwise go idle and poll
// waits for its grant right here, its word marked watched (the granter
// rings nothing): a grant then costs neither RTPU a switch, the idle
// loop's watch or a scan. Interrupts stay enabled: a tick or a ring
// preempts the spin as it would any task; a task made ready or a pending
// vector ends it, and a user signal interrupts it as it would the wait.
Spun spin_watched(std::uint32_t* word, std::uint64_t end, std::uint32_t taken) {
    for (unsigned n = 1;; ++n) {
        if (word_granted(__atomic_load_n(word, __ATOMIC_ACQUIRE))) return Spun::kGranted;
        if (port::g_irq.pending || (n & 15) == 0) {
            IrqGuard guard;  // its release takes a pending tick (and may switch)
            if (signalled_locked(taken)) return Spun::kSignalled;
            if (!only_waiting_locked()) return Spun::kOver;
            if (port::now_ns() >= end) return Spun::kSpent;
        }
        port::relax();
    }
}

}  // namespace

std::uint32_t remote_wait_initial_word() {
    if (!remote_wait_possible()) return 0;
    IrqGuard guard;
    if (!spin_limit_locked(-1)) return 0;
    // The wait begins here for user signals: the record is written next.
    g_k.current->sigs_at_wait = g_k.current->sigs_taken;
    return kWordWatched;
}

int remote_wait(std::uint32_t* word, std::int64_t timeout_ns) {
    if (!remote_wait_possible()) return -EPERM;
    const std::uint32_t v = __atomic_load_n(word, __ATOMIC_ACQUIRE);
    if (word_granted(v)) return 0;
    Tcb* cur = g_k.current;
    bool watched = v == kWordWatched;  // marked when the record was written
    const std::uint32_t taken = watched ? cur->sigs_at_wait : cur->sigs_taken;
    std::uint64_t spin_ns;
    {
        IrqGuard guard;
        spin_ns = spin_limit_locked(timeout_ns);
    }
    Spun spun = Spun::kOver;
    if (spin_ns) {
        if (!watched && move_word(word, 0, kWordWatched)) return 0;
        watched = true;
        const std::uint64_t t0 = port::now_ns();
        spun = spin_watched(word, t0 + spin_ns, taken);
        if (spun == Spun::kGranted) return 0;
        if (timeout_ns > 0) {  // the spin counts against the timeout
            const std::uint64_t spent = port::now_ns() - t0;
            timeout_ns = spent >= std::uint64_t(timeout_ns) ? 0 : timeout_ns - std::int64_t(spent);
        }
    }
    // Unwatched before parking: a grant from here on rings.
    if (watched && move_word(word, kWordWatched, 0)) return 0;
    IrqGuard guard;
    // Set before we parked: no need to wait (the ring may already be spent).
    if (word_granted(__atomic_load_n(word, __ATOMIC_ACQUIRE))) return 0;
    // A signal during the spin (or since the record was written, when the
    // spin was planned) interrupts the wait as it would the parked one.
    if (watched && signalled_locked(taken)) {
        deliver_pending_locked();
        return -EINTR;
    }
    if (timeout_ns == 0) return -ETIMEDOUT;
    // The RTPU polled already: its idle loop need not poll again first.
    if (spun == Spun::kSpent) g_k.idle_poll_spent = true;
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
