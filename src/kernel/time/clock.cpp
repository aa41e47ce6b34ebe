// Time: the timer heap behind every timed event of the RTPU (releases,
// deadlines, pauses, timeouts), the one port timer programmed for the
// earliest of them, and the virtual clock used by exact scheduling tests.
#include <cerrno>

#include "kernel.hpp"

namespace chm::kernel {

namespace {
constexpr std::uint64_t kArmSlackNs = 1000;  // far below a timer signal's latency
}  // namespace

void timer_add_locked(TimerNode* n, std::uint64_t due) {
    if (n->idx >= 0) g_k.timers.remove(n);
    n->due = due;
    g_k.timers.push(n);
}

void timer_cancel_locked(TimerNode* n) {
    if (n->idx >= 0) g_k.timers.remove(n);
}

std::uint64_t next_due_locked() {
    std::uint64_t due = 0;
    if (TimerNode* top = g_k.timers.top()) due = top->due;
    if (g_k.quantum_due && (!due || g_k.quantum_due < due)) due = g_k.quantum_due;
    return due;
}

bool timers_run_locked(std::uint64_t now) {
    bool fired = false;
    while (TimerNode* n = g_k.timers.top()) {
        if (n->due > now) break;
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

void timer_program_locked(std::uint64_t now) {
    if (g_k.cfg.virtual_clock) return;
    const std::uint64_t due = next_due_locked();
    if (!due) return;
    // Re-arm only when the new event is earlier than what is armed: a later
    // one is found by the (then early) tick, which saves a system call on
    // most kernel operations. An event at most kArmSlackNs earlier rides on
    // the armed tick: a periodic task's next release lies 1 ns before the
    // deadline the tick armed, and re-arming for it cost a timer_settime
    // (several µs on a virtual machine) in front of every other task
    // released with it.
    if (g_k.armed_at == 0 || g_k.armed_at <= now || due + kArmSlackNs < g_k.armed_at) {
        port::timer_arm_locked(due);
        g_k.armed_at = due;
    }
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
            if (must_switch_locked(g_k.vnow)) {
                reschedule_locked();
            } else if (g_k.quantum_due && g_k.vnow >= g_k.quantum_due) {
                g_k.quantum_due = 0;  // expired with nobody to rotate with
            }
        }
    }
    charge_current_locked(g_k.vnow);
}
