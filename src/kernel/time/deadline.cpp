// Deadline failures (Chimera II's deadline-failure handling), in one place:
//  * detection: each cycle's deadline timer, armed by release_cycle_locked
//    (task/task.cpp) at deadline + 1 ns and fired by timers_run_locked
//    (time/clock.cpp), calls deadline_missed_locked: the miss is counted
//    (misses, misses_unhandled, worst lateness) and owed to the task;
//  * a cycle that completes (complete_cycle_locked, from
//    chm_task_wait_period in time/periodic.cpp) cancels its deadline timer,
//    or records how late it was;
//  * the handler call: deliver_deadline_miss_locked runs in the failing
//    task's own context (deliver_pending_slow_locked, core/dispatch.cpp)
//    with the count of misses since its last call (`unhandled`), and acts
//    on the handler's answer: continue, abort-cycle or stop-RTPU. Without a
//    handler the miss becomes a kernel error signal (err/err.cpp);
//  * abort-cycle: restart_aborted_cycle_locked restarts the task's entry
//    from the top at its next release.
#include "err/err_internal.hpp"
#include "core/fiber_asan.hpp"
#include "kernel.hpp"
#include "lib/hot.hpp"

namespace chm::kernel {

void deadline_missed_locked(Tcb* t, std::uint64_t now) {
    ++t->misses;
    ++t->misses_unhandled;
    t->missed_cycle = t->cycle;
    t->missed_deadline = t->s.abs_deadline_ns;
    if (now - t->s.abs_deadline_ns > t->worst_lateness) t->worst_lateness = now - t->s.abs_deadline_ns;
    t->miss_pending = true;  // without a handler: a kernel error signal (err/)
}

CHM_HOT void complete_cycle_locked(Tcb* t, std::uint64_t now) {
    ++t->cycles_done;
    if (t->s.cycle_cpu_ns > t->worst_cycle_cpu) t->worst_cycle_cpu = t->s.cycle_cpu_ns;
    if (t->dl.idx >= 0) {
        timer_cancel_locked(&t->dl);  // finished in time
    } else if (now > t->s.abs_deadline_ns && now - t->s.abs_deadline_ns > t->worst_lateness) {
        t->worst_lateness = now - t->s.abs_deadline_ns;
    }
    t->awaiting_release = true;
}

void deliver_deadline_miss_locked(Tcb* cur) {
    cur->miss_pending = false;
    chm_deadline_info_t info{tid_of(cur),
                             cur->missed_cycle, cur->missed_deadline, now_locked(),
                             cur->misses, cur->misses_unhandled};
    cur->misses_unhandled = 0;
    chm_deadline_action act = CHM_DL_CONTINUE;
    if (cur->on_deadline) {
        const int own_prio = cur->s.priority;
        if (cur->handler_priority) cur->s.priority = cur->handler_priority;
        port::irq_restore();
        act = cur->on_deadline(&info, cur->on_deadline_arg);
        port::irq_disable();
        cur->s.priority = own_prio;
    } else {
        err_deadline_missed_locked(info);  // a kernel error signal
    }
    if (act == CHM_DL_STOP_RTPU) {
        port::irq_restore();
        chm_kernel_stop(0);
    }
    if (act == CHM_DL_ABORT_CYCLE && cur->call_depth) {
        cur->abort_cycle_owed = true;  // at a backplane call's wait: done when the call returns
    } else if (act == CHM_DL_ABORT_CYCLE) {
        cur->abort_cycle = true;
        port::irq_restore();
        chm_task_wait_period();  // restarts the entry at the next release
        port::irq_disable();
    }
}

namespace {

// The restart proper, on a frame the caller placed below the top
// kMinStack bytes of the stack (see below).
[[noreturn]] __attribute__((noinline)) void restart_from_below(Tcb* cur) {
    port::context_init(&cur->ctx, cur->stack_lo, cur->stack_size, task_start, cur);
    asan::switch_begin(nullptr, cur->stack_lo, cur->stack_size);  // these frames for good
    void* discard;
    chm_port_switch(&discard, cur->ctx.sp);
    __builtin_unreachable();
}

}  // namespace

void restart_aborted_cycle_locked(Tcb* cur) {
    // Restart the entry from the top, on this same stack. context_init
    // writes the entry frame just under the stack's top; this function's
    // own frame and the switch's save area lie just under the stack
    // pointer. An aborted cycle's frames can be shallow (an entry that
    // tail-called the aborted call left 160 bytes on aarch64, whose entry
    // frame is 176), and then the switch stored the old stack pointer
    // into a local that overlapped the new frame's argument slot: the
    // restarted entry got a garbage argument. Step below the top
    // kMinStack bytes first: nothing of ours is written there after the
    // frame, and none of these frames is returned to.
    cur->abort_cycle = false;
    char here;
    const auto sp = reinterpret_cast<std::uintptr_t>(&here);
    const auto floor = reinterpret_cast<std::uintptr_t>(cur->stack_lo) + cur->stack_size - port::kMinStack;
    if (sp > floor - 64) {
        void* pad = __builtin_alloca(sp - floor + 64);
        asm volatile("" : : "r"(pad) : "memory");  // keep the step down
    }
    restart_from_below(cur);
}

}  // namespace chm::kernel
