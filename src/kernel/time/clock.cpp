// Time: the timer heap behind every timed event of the RTPU (releases,
// deadlines, pauses, timeouts), the one port timer programmed for the
// earliest of them, and the virtual clock used by exact scheduling tests.
#include <cerrno>

#include "kernel.hpp"
#include "lib/hot.hpp"

namespace chm::kernel {

namespace {
constexpr std::uint64_t kMinRepeatNs = 50000;  // shortest interval worth repeating
}  // namespace

CHM_HOT void timer_add_locked(TimerNode* n, std::uint64_t due) {
    CHM_ASSERT_LOCKED();
    if (n->idx >= 0) g_k.timers.remove(n);
    n->due = due;
    g_k.timers.push(n, timer_order(n));
}

void timer_remove_locked(TimerNode* n) { g_k.timers.remove(n); }

std::uint64_t next_due_locked() {
    std::uint64_t due = 0;
    if (g_k.timers.size()) due = g_k.timers.top_due();
    if (!g_k.current) return due;  // a quantum is the running task's
    if (g_k.quantum_due && (!due || g_k.quantum_due < due)) due = g_k.quantum_due;
    // A quantum left to the armed tick: a re-arm (only ever for an earlier
    // event, or after that tick passed) must not drop its end.
    if (g_k.quantum_lazy) {
        const std::uint64_t end = g_k.slice_start + g_k.cfg.quantum_ns;
        if (!due || end < due) due = end;
    }
    return due;
}

CHM_HOT bool timers_run_locked(std::uint64_t now) {
    CHM_ASSERT_LOCKED();
    bool fired = false;
    while (g_k.timers.size() && g_k.timers.top_due() <= now) {
        TimerNode* n = g_k.timers.top();
        g_k.timers.remove(n);
        fired = true;
        Tcb* t = n->owner;
        switch (n->kind) {
        case TimerKind::Wake:
            if (t->state == TaskState::Paused) {
                t->wait_result = 0;
                make_ready_locked(t);
            } else if (t->state == TaskState::Blocked) {
                wake_locked(t, -ETIMEDOUT);
            }
            break;
        case TimerKind::Release:
            if (t->state == TaskState::WaitPeriod) {
                release_cycle_locked(t, n->due);
                make_ready_locked(t);
            } else {  // it is still running (or handling a signal): owed
                t->release_pending = true;
                t->pending_release = n->due;
            }
            break;
        case TimerKind::Deadline:
            deadline_missed_locked(t, now);
            break;
        case TimerKind::IoPoll:
            io_tick_locked(now);
            break;
        }
    }
    return fired;
}

// What follows the event at `due` (the top of the timer heap): the
// nearer of the next event the heap holds beyond that instant (and its
// slack), and what the top event itself brings: a release creates its
// cycle's deadline (deadline + 1 later), a deadline is followed by the next
// cycle's (a period later). Armed as the timer's interval, so the tick
// that releases a periodic set finds the timer already set for what comes
// next: no system call. The heap's next event matters when tasks are
// released in turn (4 tasks of period 2 ms, 500 us apart: with the top's
// own guess alone, 2 ms, every tick re-armed the timer).
std::uint64_t next_gap_guess_locked(std::uint64_t due) {
    const TimerNode* top = g_k.timers.top();
    if (!top || top->due != due) return 0;
    std::uint64_t gap = 0;
    if (top->owner) {
        const chm_sched_task_t& s = top->owner->s;
        if (top->kind == TimerKind::Release) gap = s.deadline_ns + 1;
        if (top->kind == TimerKind::Deadline) gap = s.period_ns;
    }
    if (const std::uint64_t next = g_k.timers.next_due_after(due + kArmSlackNs))
        if (!gap || next - due < gap) gap = next - due;
    return gap >= kMinRepeatNs ? gap : 0;  // never a storm of ticks
}

CHM_HOT void timer_program_locked(std::uint64_t now) {
    if (g_k.cfg.virtual_clock) return;
    const std::uint64_t due = next_due_locked();
    const bool repeating = port::timer_interval() != 0;
    if (!due) {
        if (repeating) {  // nothing to wait for: stop a repeating timer
            port::timer_arm_locked(0);
            g_k.armed_at = 0;
        }
        return;
    }
    // Re-arm only when the new event is earlier than what is armed: a later
    // one is found by the (then early) tick, which saves a system call on
    // most kernel operations. An event at most kArmSlackNs earlier rides on
    // the armed tick: a periodic task's next release lies 1 ns before the
    // deadline the tick armed, and re-arming for it cost a timer_settime
    // (several µs on a virtual machine) in front of every other task
    // released with it. A repeating timer is re-armed for a later event
    // too, so it never ticks on for nothing.
    const bool stale = g_k.armed_at == 0 || g_k.armed_at <= now;
    const bool too_late = due + kArmSlackNs < g_k.armed_at;
    const bool too_early = repeating && g_k.armed_at + kArmSlackNs < due;
    if (stale || too_late || too_early) {
        port::timer_arm_locked(due, next_gap_guess_locked(due));
        g_k.armed_at = due;
    }
}

CHM_HOT void idle_tick_locked() {
    const std::uint64_t t = now_exact_locked();
    timer_fired_locked(t);
    timers_run_locked(t);
    timer_program_locked(t);
}

CHM_HOT void timer_fired_locked(std::uint64_t now) {
    const std::uint64_t every = port::timer_interval();
    if (!every || !g_k.armed_at) {
        g_k.armed_at = 0;  // a one-shot fired (or a retry replaced it): nothing armed
        return;
    }
    while (g_k.armed_at <= now) g_k.armed_at += every;  // it fires again by itself
}

}  // namespace chm::kernel

using namespace chm::kernel;
namespace port = chm::port;

extern "C" uint64_t chm_time_now(void) { return now_locked(); }

extern "C" void chm_time_consume(uint64_t ns) {
    if (!g_k.cfg.virtual_clock) {
        const std::uint64_t end = chm::port::now_ns() + ns;
        while (chm::port::now_ns() < end) chm::port::relax();
        return;
    }
    IrqGuard guard;
    // The decision of the instant the caller's last work ended (below).
    if (g_k.decision_owed) {
        g_k.decision_owed = false;
        if (decide_at_event_locked(g_k.vnow)) reschedule_locked();
    }
    std::uint64_t left = ns;
    while (left) {
        const std::uint64_t due = next_due_locked();
        std::uint64_t step = left;
        if (due && due > g_k.vnow && due - g_k.vnow < step) step = due - g_k.vnow;
        if (due && due <= g_k.vnow) step = 0;
        g_k.vnow += step;
        left -= step;
        if (due && g_k.vnow >= due) {
            timers_run_locked(g_k.vnow);
            if (!left) {
                // The work ends at this very instant: it completes before
                // what fired is acted on (a job done at its deadline is on
                // time, whoever is released then). The caller's next call
                // into the kernel decides.
                g_k.decision_owed = true;
                break;
            }
            if (decide_at_event_locked(g_k.vnow)) reschedule_locked();
        }
    }
    charge_current_locked(g_k.vnow);
}
