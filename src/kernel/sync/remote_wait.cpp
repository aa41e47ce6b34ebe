// Tasks parked on shared-memory words (sync/remote_wait.hpp). The waiters
// of all words are one list: a grant rings the RTPU once and the handler
// scans it (a handful of remote waits per RTPU, so a scan beats an index).
#include <cerrno>

#include "kernel.hpp"
#include "task/holds.hpp"
#include "sync/remote_wait.hpp"
#include "lib/hot.hpp"

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

std::uint32_t task_id(const Tcb* t) { return tid_short(t) + 1; }  // a 32-bit shared word

// A task's place in its RTPU's order as one number another process can
// compare (port::RingFor): a grant interrupts the running task when the
// waiter's number is higher than the one published for it. Only the
// static part of the policy's order is in it:
//  * the class (top bits), classes that never mix: MUF's critical set
//    before the rest; within that, tasks with a deadline (RM: a period)
//    before tasks without, which every built-in policy orders by priority;
//  * within a class, the priority (FIXED, and tasks without a deadline),
//    or RM's period (coarsened to 28 bits: a waiter in the running task's
//    bucket interrupts it);
//  * where the order moves while a task runs (EDF's deadlines, MLF's and
//    MUF's laxity) a waiter's number is its class's highest and the
//    running task's its lowest: the grant interrupts and the RTPU's own
//    scheduler decides, as under a user policy (always).
// The running task's number is republished at every switch and by
// schedule_locked (a priority or flag changed without one).
enum class Side { kWaiter, kRunning };

constexpr int kLowBits = 29;
constexpr std::uint32_t kLowMax = (1u << kLowBits) - 1;

// 1 .. kLowMax - 1; a priority beyond that scale is the top for a waiter
// and the bottom for the running task: the grant interrupts.
std::uint32_t by_priority(int priority, Side side) {
    constexpr int kHalf = 1 << (kLowBits - 1);
    if (priority <= -kHalf || priority >= kHalf - 1) return side == Side::kWaiter ? kLowMax : 0;
    return std::uint32_t(priority + kHalf);
}

// Shorter periods higher: 6 bits of exponent and 22 of mantissa, doubled
// so that a waiter in the running task's bucket is higher.
std::uint32_t by_period(std::uint64_t period, Side side) {
    const int exp = 63 - __builtin_clzll(period);
    const std::uint64_t mant = exp > 22 ? period >> (exp - 22) : period << (22 - exp);
    const std::uint32_t key = std::uint32_t(exp) << 22 | std::uint32_t(mant & ((1u << 22) - 1));
    return 2 * (((1u << 28) - 1) - key) + (side == Side::kWaiter ? 1 : 0);
}

std::uint32_t order_number(const chm_sched_task_t& s, Side side) {
    if (!g_k.builtin) return side == Side::kWaiter ? UINT32_MAX : 0;
    if (g_k.policy == CHM_SCHED_FIXED) return by_priority(s.priority, side);
    const std::uint64_t major = rq_key(g_k.policy, &s).major;
    const bool keyed = (major & kKeyNever) != kKeyNever;  // a deadline (RM: a period)
    const bool critical = g_k.policy == CHM_SCHED_MUF && !(major >> 63);
    const std::uint32_t cls = (critical ? 2u : 0u) + (keyed ? 1u : 0u);
    std::uint32_t low;
    if (!keyed) low = by_priority(s.priority, side);
    else if (g_k.policy == CHM_SCHED_RM) low = by_period(major, side);
    else low = side == Side::kWaiter ? kLowMax : 0;
    return cls << kLowBits | low;
}

}  // namespace

std::uint32_t remote_waiter_id() { return remote_wait_possible() ? task_id(g_k.current) : 0; }

std::uint32_t remote_waiter_urgency() {
    const Tcb* cur = port::on_kernel_thread() ? g_k.current : nullptr;
    return cur ? order_number(cur->s, Side::kWaiter) : UINT32_MAX;
}

CHM_HOT void publish_running_locked() {
    const Tcb* t = g_k.current;
    if (!t) return port::doorbell_publish_locked(0, 0);
    port::doorbell_publish_locked(task_id(t), order_number(t->s, Side::kRunning));
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
// poll, when the RTPU polls and has nothing else to do, but never past
// `deadline` (kernel clock, which is port::now_ns() whenever spinning is
// possible: not on the virtual clock). Mask held.
std::uint64_t spin_limit_locked(std::uint64_t deadline) {
    const std::uint64_t poll = g_k.cfg.idle_poll_ns;
    if (!poll || g_k.cfg.virtual_clock || io_watching_locked()) return 0;
    if (!only_waiting_locked()) return 0;
    if (deadline == CHM_FOREVER) return poll;
    const std::uint64_t now = now_locked();
    if (now >= deadline) return 0;
    return deadline - now < poll ? deadline - now : poll;
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
    if (!spin_limit_locked(CHM_FOREVER)) return 0;
    // The wait begins here for user signals: the record is written next.
    g_k.current->sigs_at_wait = g_k.current->sigs_taken;
    return kWordWatched;
}

bool clock_is_virtual() { return g_k.cfg.virtual_clock != 0; }

namespace {

int wait_for_word(std::uint32_t* word, std::uint64_t deadline) {
    const std::uint32_t v = __atomic_load_n(word, __ATOMIC_ACQUIRE);
    if (word_granted(v)) return 0;
    Tcb* cur = g_k.current;
    bool watched = v == kWordWatched;  // marked when the record was written
    const std::uint32_t taken = watched ? cur->sigs_at_wait : cur->sigs_taken;
    std::uint64_t spin_ns;
    {
        IrqGuard guard;
        spin_ns = spin_limit_locked(deadline);
    }
    Spun spun = Spun::kOver;
    if (spin_ns) {
        if (!watched && move_word(word, 0, kWordWatched)) return 0;
        watched = true;
        const std::uint64_t t0 = port::now_ns();
        spun = spin_watched(word, t0 + spin_ns, taken);
        if (spun == Spun::kGranted) return 0;
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
    const std::uint64_t now = now_locked();
    if (now >= deadline) return -ETIMEDOUT;  // the spin counted against it too
    // The RTPU polled already: its idle loop need not poll again first.
    if (spun == Spun::kSpent) g_k.idle_poll_spent = true;
    cur->rword = word;
    cur->state = TaskState::Blocked;
    cur->interruptible = true;
    cur->wait_result = 0;
    waitq_insert_locked(&g_remote, cur);
    ++g_k.remote_parks;
    if (deadline != CHM_FOREVER) {
        cur->tmr.kind = TimerKind::Wake;
        timer_add_locked(&cur->tmr, deadline);
        timer_program_locked(now);
    }
    // A grant between the test above and here rang the doorbell: its
    // dispatch runs before any other task and finds us in the list.
    const int r = block_current_locked();
    cur->rword = nullptr;
    deliver_pending_locked();
    return r;
}

}  // namespace

int remote_wait(std::uint32_t* word, std::uint64_t deadline) {
    if (!remote_wait_possible()) return -EPERM;
    // The wait of a backplane call is its cancellation point: handlers
    // held back while it ran may run here, and a destroy or abort-cycle
    // owed to the task ends the wait (-EINTR: the call withdraws as for
    // a user signal, and the owed end follows when it returns). A grant
    // already taken is kept: the call completes first.
    Tcb* cur = g_k.current;
    const bool was = cur->at_cancel_point;
    cur->at_cancel_point = true;
    int r;
    {
        IrqGuard guard;
        deliver_pending_locked();
    }
    if (cancel_owed()) r = word_granted(__atomic_load_n(word, __ATOMIC_ACQUIRE)) ? 0 : -EINTR;
    else r = wait_for_word(word, deadline);
    if (r != 0 && cancel_owed()) r = -EINTR;
    cur->at_cancel_point = was;
    return r;
}

}  // namespace chm::kernel
