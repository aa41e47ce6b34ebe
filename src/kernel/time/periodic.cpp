// Task timing: pause until a restart time, periodic cycles on an
// absolute grid (no drift), and locking a task into the CPU. What happens
// when a cycle misses its deadline is in time/deadline.cpp.
#include <cerrno>

#include "kernel.hpp"
#include "err/err_internal.hpp"
#include "lib/hot.hpp"

namespace chm::kernel {

namespace {

// Block the current task until `until` (Paused) or its next release
// (WaitPeriod); user signals interrupt the wait.
CHM_HOT int sleep_current_locked(TaskState state, std::uint64_t until, TimerKind kind) {
    Tcb* cur = g_k.current;
    cur->state = state;
    cur->interruptible = true;
    cur->wait_result = 0;
    cur->tmr.kind = kind;
    timer_add_locked(&cur->tmr, until);
    timer_program_locked(now_locked());
    const int r = block_current_locked();
    deliver_pending_locked();
    return r;
}

}  // namespace

}  // namespace chm::kernel

using namespace chm::kernel;
namespace port = chm::port;

extern "C" {

// chm_task_yield: core/dispatch.cpp (the dispatcher's fast path).

int chm_task_pause_until(uint64_t restart_ns) {
    IrqGuard guard;
    if (!g_k.current) return record_failure(-EPERM, "chm_task_pause_until");
    if (restart_ns <= now_locked()) return 0;
    return sleep_current_locked(TaskState::Paused, restart_ns, TimerKind::Wake);
}

CHM_HOT int chm_task_wait_period(void) {
    port::irq_disable();
    Tcb* cur = g_k.current;
    if (!cur || !cur->s.period_ns) {
        port::irq_restore();
        return record_failure(-EINVAL, "chm_task_wait_period");
    }
    const std::uint64_t now = now_locked();
    charge_current_locked(now);  // statistical when cpu_accounting is 0
    if (!cur->awaiting_release) complete_cycle_locked(cur, now);
    int r = 0;
    const std::uint64_t next = cur->s.release_ns + cur->s.period_ns;
    if (cur->release_pending || (next <= now && !cur->abort_cycle)) {
        // The next cycle is already due (we ran late, or a signal took us
        // from the wait when it came): a new job, which queues behind its
        // equals like any release, and the scheduler decides who runs.
        release_cycle_locked(cur, cur->release_pending ? cur->pending_release : next);
        if (!cur->lock_nest) {
            make_ready_locked(cur);
            schedule_locked();
            deliver_pending_locked();
        }
    } else {
        r = sleep_current_locked(TaskState::WaitPeriod, next, TimerKind::Release);
    }
    if (cur->abort_cycle && r == 0) restart_aborted_cycle_locked(cur);  // time/deadline.cpp
    port::irq_restore();
    return r;
}

CHM_HOT uint64_t chm_task_cycle_release(void) {
    Tcb* cur = g_k.current;
    return cur && cur->s.period_ns ? cur->s.release_ns : 0;
}

void chm_task_lock(void) {
    IrqGuard guard;
    if (g_k.current) ++g_k.current->lock_nest;
}

void chm_task_unlock(void) {
    IrqGuard guard;
    Tcb* cur = g_k.current;
    if (!cur || !cur->lock_nest) return;
    if (--cur->lock_nest == 0) {
        // Ticks were counted while locked; act on them now.
        const std::uint64_t now = now_locked();
        timers_run_locked(now);
        timer_program_locked(now);
        reschedule_locked();
    }
}

}  // extern "C"
