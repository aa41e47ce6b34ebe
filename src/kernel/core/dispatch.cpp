// Dispatching: who runs, the switch itself, and the three ways into it —
// a kernel call that blocks or wakes (task context), the timer signal
// redirected through the port's preemption trampoline, and a tick that
// arrived while the mask was held (irq_restore's pending hook).
#include <cerrno>
#include <cstdlib>
#include <sys/syscall.h>
#include <unistd.h>

#include "core/fiber_asan.hpp"
#include "kernel.hpp"
#include "sync/remote_wait.hpp"
#include "lib/hot.hpp"

namespace chm::kernel {

Kernel g_k;

// A `_locked` entry found the mask free (CHM_ASSERT_LOCKED, assertion
// builds only): a caller broke the calling-context rule. The write system
// call only: it may be a signal handler, and libc's write may be
// interposed (io/).
void mask_not_held(const char* fn) {
    static const char head[] = "chimera: ";
    static const char tail[] = " called without the interrupt mask held\n";
    std::size_t n = 0;
    while (fn[n]) ++n;
    (void)!::syscall(SYS_write, 2, head, sizeof head - 1);
    (void)!::syscall(SYS_write, 2, fn, n);
    (void)!::syscall(SYS_write, 2, tail, sizeof tail - 1);
    std::abort();
}

CHM_HOT void make_ready_locked(Tcb* t, bool keep_place) {
    if (t->suspend_count) {  // a suspended task's wait ended: stay suspended
        t->state = TaskState::Suspended;
        return;
    }
    t->state = TaskState::Ready;
    if (!keep_place) t->s.seq = ++g_k.seq;
    if (!t->in_ready) {
        t->in_ready = true;
        sched_enqueue_locked(t);
    }
}

CHM_HOT void unready_queued_locked(Tcb* t) {
    t->in_ready = false;
    sched_dequeue_locked(t);
}

// Can `head`, waiting, come before the running task `t` without an event?
// Only where the order moves with time: under MLF and MUF a waiting task's
// laxity shrinks while the running one's stays, so a waiting task with a
// deadline (in MUF's same class) may overtake; a user policy may do
// anything. RM, EDF and FIXED keys only change at events.
inline bool may_overtake_locked(const Tcb* head, const Tcb* t) {
    switch (g_k.policy) {
    case CHM_SCHED_MLF: return head->s.abs_deadline_ns != UINT64_MAX;
    case CHM_SCHED_MUF:
        return head->s.abs_deadline_ns != UINT64_MAX &&
               ((head->s.flags ^ t->s.flags) & kInCriticalSet) == 0;
    case CHM_SCHED_USER: return true;
    default: return false;
    }
}

// sched_before_locked(t, head) for `head` the scheduler's pick, `t` not
// queued: under a built-in policy from the key `head` was queued with.
inline bool runs_before_head_locked(Tcb* t, Tcb* head, std::uint64_t now) {
    if (g_k.builtin) return g_k.rq.top_strictly_after(rq_key(g_k.policy, &t->s));
    return sched_before_locked(t, head, now);
}

// The running task's quanta end at slice_start + k * quantum (sched.h).
// An end that was not armed (nobody to rotate with until this instant)
// still counts when an event lands on it exactly: on the virtual clock,
// where instants coincide; on the real clock they do not, and the
// division is skipped.
bool quantum_expired_locked(std::uint64_t now) {
    const std::uint64_t q = g_k.cfg.quantum_ns;
    if (!q || now <= g_k.slice_start) return false;
    if (g_k.quantum_due && now >= g_k.quantum_due) return true;
    if (g_k.quantum_lazy) return now - g_k.slice_start >= q;  // its tick came late
    return g_k.cfg.virtual_clock && (now - g_k.slice_start) % q == 0;
}

// Arm the end of `t`'s current quantum, but only when a decision there can
// change anything (tickless): an equal task waits (round robin), or the
// waiting head may overtake it as time passes (quantum_arm_locked). This
// is its body, for a quantum `q` whose end is not armed (quantum_due 0),
// inline in the switch, which starts every slice.
inline __attribute__((always_inline)) void quantum_arm_fresh_locked(Tcb* t, std::uint64_t now,
                                                                    std::uint64_t q) {
    Tcb* head = sched_pick_locked(now);
    if (!head || (!may_overtake_locked(head, t) && runs_before_head_locked(t, head, now))) return;
    std::uint64_t due = g_k.slice_start + q;
    if (now >= due) due += (now - due) / q * q + q;  // the first end after now
    // A timer due first is a decision point that arms it then: a periodic
    // set whose releases come before each quantum's end costs no timer
    // re-arm per switch.
    if (const TimerNode* top = g_k.timers.top(); top && top->due <= due) return;
    g_k.quantum_due = due;
    // The earliest event now; usually an earlier quantum's tick serves it.
    if (!timer_serves_locked(due, now)) timer_program_locked(now);
}

void quantum_arm_locked(Tcb* t, std::uint64_t now) {
    const std::uint64_t q = g_k.cfg.quantum_ns;
    if (!q || g_k.quantum_due > now) return;
    g_k.quantum_due = 0;
    g_k.quantum_lazy = false;
    quantum_arm_fresh_locked(t, now, q);
}

// The switch to `next` starts its slice at `now`. When a one-shot tick is
// armed after `now` and at or before the slice's first quantum end, the
// arming waits for the slice's first event (that tick at the latest):
// every event while `next` runs calls quantum_arm_locked, which arms it
// then. A run of switches between tasks that yield (a switch every few
// tens of ns, one tick per quantum) then skips the pick, the key and the
// compare at each switch (~4 ns of a ~30 ns yield). Only a one-shot: a
// repeating timer may be moved later without ticking; and the virtual
// clock has no armed tick (armed_at 0), so it always arms here.
inline __attribute__((always_inline)) void quantum_arm_at_switch_locked(Tcb* next, std::uint64_t now,
                                                                        std::uint64_t q) {
    if (g_k.armed_at > now && g_k.armed_at <= now + q && !port::timer_interval()) {
        g_k.quantum_lazy = true;
        return;
    }
    quantum_arm_fresh_locked(next, now, q);
}

bool must_switch_locked(std::uint64_t now) {
    Tcb* cur = g_k.current;
    if (!cur) return false;
    if (cur->state != TaskState::Running) return true;
    if (cur->lock_nest) return false;  // locked into the CPU
    if (cur->sig_pending & ~cur->sig_blocked) return true;
    if (cur->miss_pending) return true;
    Tcb* head = sched_pick_locked(now);
    if (!head) return false;
    if (sched_before_locked(head, cur, now)) return true;
    // Round robin among equals at the end of a quantum.
    return quantum_expired_locked(now) && !sched_before_locked(cur, head, now);
}

bool decide_at_event_locked(std::uint64_t now) {
    if (!g_k.current) return false;
    charge_current_locked(now);  // the running task's laxity as of now
    if (must_switch_locked(now)) return true;
    quantum_arm_locked(g_k.current, now);
    return false;
}

namespace {

// Switch from the current context (a task or the kernel's own) to `next`
// (nullptr = the kernel's idle loop). Returns in the original context when
// it is scheduled again.
// Never inlined: it must stay the one call site of the port switch.
CHM_HOT __attribute__((noinline)) void switch_to_locked(Tcb* next, std::uint64_t now) {
    Tcb* prev = g_k.current;
    port::Context* from = prev ? &prev->ctx : &g_k.idle_ctx;
    port::Context* to = next ? &next->ctx : &g_k.idle_ctx;
    int* err = g_k.errno_loc;  // errno without a TLS lookup per switch
    if (prev) prev->saved_errno = *err;
    g_k.current = next;
    if (port::g_db_publishes) publish_running_locked();
    if (g_k.cfg.cpu_accounting) g_k.switched_in_at = now;
    g_k.slice_start = now;
    g_k.quantum_due = 0;
    g_k.quantum_lazy = false;
    if (const std::uint64_t q = g_k.cfg.quantum_ns; next && q) quantum_arm_at_switch_locked(next, now, q);
    ++g_k.switches;
    if (g_k.trace_switch) [[unlikely]] g_k.trace_switch(next, now);
    // Leaving for good (an ended task): no save slot, its fake stack goes.
    void* asan_save = nullptr;
    asan::switch_begin(prev && prev == g_k.zombie ? nullptr : &asan_save,
                       next ? next->stack_lo : nullptr, next ? next->stack_size : 0);
    port::steer_branch_history(next ? next->index : 0);
    port::context_switch_same_site(from, to);  // the kernel's only switch site
    asan::switch_end(asan_save);
    // Back in `prev`'s context.
    if (Tcb* z = g_k.zombie) [[unlikely]] {  // its stack is no longer in use
        g_k.zombie = nullptr;
        task_free_stack_locked(z);
    }
    if (g_k.current) *err = g_k.current->saved_errno;
}

// The running task `cur` gives the CPU to `head`, the scheduler's pick:
// behind its equals (keep_place false) or first among them (preempted).
// Under a built-in policy `cur` takes the top's place in the heap: one sift
// instead of a push and a pop.
inline __attribute__((always_inline)) void requeue_and_switch_locked(Tcb* cur, Tcb* head, bool keep_place,
                                                                 std::uint64_t now) {
    if (g_k.builtin && !cur->in_ready && !cur->suspend_count) {
        cur->state = TaskState::Ready;
        if (!keep_place) cur->s.seq = ++g_k.seq;
        cur->in_ready = true;
        head->in_ready = false;
        g_k.rq.replace_top(cur, rq_key(g_k.policy, &cur->s));
    } else {
        make_ready_locked(cur, keep_place);
        unready_locked(head);
    }
    head->state = TaskState::Running;
    switch_to_locked(head, now);
}

// The running task `cur` against the pick `head` under a built-in policy:
// the decision of schedule_at_locked with one key computed (`head`'s is
// the one it was queued with) and used again for the requeue.
inline __attribute__((always_inline)) void decide_builtin_locked(Tcb* cur, Tcb* head, std::uint64_t now) {
    RqKey k = rq_key(g_k.policy, &cur->s);
    const bool preempted = g_k.rq.top_before(k);
    if (!preempted && (g_k.rq.top_strictly_after(k) || !quantum_expired_locked(now))) {
        quantum_arm_locked(cur, now);
        return;
    }
    if (!preempted) k.seq = cur->s.seq = ++g_k.seq;  // round robin: behind its equals
    cur->state = TaskState::Ready;
    cur->in_ready = true;
    head->in_ready = false;
    g_k.rq.replace_top(cur, k);
    head->state = TaskState::Running;
    switch_to_locked(head, now);
}

}  // namespace

void schedule_locked() { schedule_at_locked(schedule_now_locked()); }

CHM_HOT void schedule_at_locked(std::uint64_t now) {
    CHM_ASSERT_LOCKED();
    // A priority changed without a switch (set, lent, handler) is published too.
    if (port::g_db_publishes) publish_running_locked();
    g_k.decision_owed = false;
    Tcb* cur = g_k.current;
    const bool cur_runs = cur && cur->state == TaskState::Running;
    if (cur_runs && cur->lock_nest) return;
    Tcb* head = sched_pick_locked(now);
    if (cur_runs) {
        if (!head) return;
        if (g_k.builtin) {  // a running task is neither queued nor suspended
            decide_builtin_locked(cur, head, now);
            return;
        }
        if (sched_before_locked(head, cur, now)) {
            requeue_and_switch_locked(cur, head, true, now);  // preempted
            return;
        }
        if (!sched_before_locked(cur, head, now) && quantum_expired_locked(now)) {
            requeue_and_switch_locked(cur, head, false, now);  // round robin
            return;
        }
        quantum_arm_locked(cur, now);
        return;
    }
    if (head) {
        unready_locked(head);
        head->state = TaskState::Running;
    }
    if (head == cur) {  // it took the CPU straight back (a late release): same slice
        if (cur) quantum_arm_locked(cur, now);
        return;
    }
    switch_to_locked(head, now);
}

namespace {

// A yield under built-in policy P: the same decision as make_ready +
// schedule, in one heap operation with the key computed once. The
// yielder's seq is the newest, so its key sorts before the top's only when
// the policy puts it strictly first: then it keeps the CPU.
template <chm_sched_policy P>
inline __attribute__((always_inline)) void yield_builtin_locked(Tcb* cur, std::uint64_t now) {
    cur->s.seq = ++g_k.seq;
    const RqKey k = rq_key<P>(&cur->s);
    if (!g_k.rq.size() || g_k.rq.top_after(k)) return;
    Tcb* head = g_k.rq.top();
    cur->state = TaskState::Ready;
    cur->in_ready = true;
    head->in_ready = false;
    g_k.rq.replace_top(cur, k);
    head->state = TaskState::Running;
    switch_to_locked(head, now);
}

}  // namespace

namespace {

// Everything but a yield under a built-in policy from a plain running task.
__attribute__((noinline, cold)) void yield_slow_locked(Tcb* cur) {
    make_ready_locked(cur);  // behind its equals
    reschedule_locked();
}

// Yield the CPU to the next task at least as urgent (behind its equals).
inline __attribute__((always_inline)) void yield_current_locked() {
    Tcb* cur = g_k.current;
    // A Running task is neither queued nor suspended (both leave Running).
    if (!g_k.builtin || g_k.in_irq || cur->state != TaskState::Running) [[unlikely]] {
        yield_slow_locked(cur);
        return;
    }
    // The clock only when the switch uses it (accounting, quantum).
    const std::uint64_t now = g_k.switch_timed ? schedule_now_locked() : 0;
    switch (g_k.policy) {
    case CHM_SCHED_FIXED: yield_builtin_locked<CHM_SCHED_FIXED>(cur, now); break;
    case CHM_SCHED_RM: yield_builtin_locked<CHM_SCHED_RM>(cur, now); break;
    case CHM_SCHED_EDF: yield_builtin_locked<CHM_SCHED_EDF>(cur, now); break;
    case CHM_SCHED_MLF: yield_builtin_locked<CHM_SCHED_MLF>(cur, now); break;
    default: yield_builtin_locked<CHM_SCHED_MUF>(cur, now); break;
    }
    deliver_pending_locked();
}

}  // namespace
}  // namespace chm::kernel

namespace {
void task_yield() {
    using namespace chm::kernel;
    chm::port::irq_disable();
    if (g_k.current) [[likely]] yield_current_locked();
    chm::port::irq_restore();
}
}  // namespace

// Here rather than with the other timing calls (time/periodic.cpp) so the
// whole yield inlines into one function; returns through the port's
// indirect return (a yield returns to another task's caller).
extern "C" void chm_task_yield(void) { chm::port::call_indirect_return(task_yield); }

namespace chm::kernel {

CHM_HOT int block_current_locked() {
    CHM_ASSERT_LOCKED();
    Tcb* cur = g_k.current;
    if (g_k.in_irq) {
        // An interrupt handler may not wait: undo the block, refuse.
        waitq_remove_locked(cur);
        timer_cancel_locked(&cur->tmr);
        cur->interruptible = false;
        cur->state = TaskState::Running;
        return -EPERM;
    }
    schedule_locked();
    return cur->wait_result;
}

void deliver_pending_slow_locked() {
    for (;;) {
        Tcb* cur = g_k.current;
        if (!cur || (cur->call_depth && !cur->at_cancel_point)) return;  // held for the call's wait or return
        if (cur->miss_pending) {
            deliver_deadline_miss_locked(cur);  // time/deadline.cpp
            continue;
        }
        const std::uint32_t sigs = cur->sig_pending & ~cur->sig_blocked;
        if (!sigs) return;
        const int signo = __builtin_ctz(sigs);
        cur->sig_pending &= ~(1u << signo);
        ++cur->sigs_taken;
        chm_usig_handler_t h = cur->sig_handled & (1u << signo) ? cur->sig_handler[signo] : nullptr;
        if (h) {
            void* a = cur->sig_arg[signo];
            port::irq_restore();
            h(signo, a);
            port::irq_disable();
        }
    }
}

void reschedule_locked() {
    // In an interrupt handler the switch waits until the handler returns
    // (the tick that ran it checks must_switch_locked).
    if (!g_k.current || g_k.in_irq) return;
    schedule_locked();
    deliver_pending_locked();
}

void reschedule_at_locked(std::uint64_t now) {
    if (!g_k.current || g_k.in_irq) return;
    if (g_k.cfg.cpu_accounting) charge_current_locked(now);
    schedule_at_locked(now);
    deliver_pending_locked();
}

namespace {

// The port's preemption trampoline calls this in the interrupted task's
// context, mask held.
void preempted_from_trampoline() {
    reschedule_locked();
    port::irq_restore();
}

// A tick, or doorbell vectors left behind a switch, that arrived while the
// mask was held; runs with the mask held.
CHM_HOT void pending_tick_locked(std::uint32_t why) {
    const std::uint64_t now = why & port::kPendingTick ? now_exact_locked() : now_locked();
    if (why & port::kPendingTick) {
        // It may be the port's own retry (a deferred preemption) that
        // fired, not what the kernel armed: forget a one-shot (re-armed
        // below).
        timer_fired_locked(now);
    }
    irq_dispatch_locked();
    if (why & port::kPendingTick) {
        timers_run_locked(now);
        timer_program_locked(now);
    }
    if (decide_at_event_locked(now)) reschedule_locked();
}

// The timer signal, on the alternate stack, mask held by the port.
CHM_HOT bool tick_from_signal(std::uint64_t now) {
    ++g_k.ticks;
    g_k.now_cache = now;
    timer_fired_locked(now);
    irq_dispatch_locked();
    timers_run_locked(now);
    // Charged here in both accounting modes (statistical without per-switch
    // accounting): MLF's and MUF's laxity of the running task needs it.
    const bool sw = decide_at_event_locked(now);
    timer_program_locked(now);
    return sw;
}

}  // namespace

void dispatch_install_hooks() {
    port::irq_set_pending_hook(pending_tick_locked);
    port::chm_port_preempt_hook = preempted_from_trampoline;
}

port::TickHandler dispatch_tick_handler() { return tick_from_signal; }

}  // namespace chm::kernel
