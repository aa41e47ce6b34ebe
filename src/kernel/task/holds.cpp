// A task's holds inside backplane calls and the ends that wait for the
// call (holds.hpp has the design).
#include "task/holds.hpp"

#include <atomic>

#include "kernel.hpp"

namespace chm::kernel {

std::atomic<bool> g_tasks_exist{false};

namespace {

// The task making this call, or nullptr (a host thread, the monitor
// thread, an interrupt handler: their holds are the process's to recover).
Tcb* caller() {
    if (!port::on_kernel_thread() || g_k.in_irq) return nullptr;
    return g_k.current;
}

// A cancel is owed to `t`: a spinning wait sees sigs_taken move (as for a
// user signal), a parked one is woken with -EINTR, a suspended one goes on
// (it is ending: its suspension no longer matters).
void cancel_wait_locked(Tcb* t) {
    ++t->sigs_taken;
    t->suspend_count = 0;
    if (t->state == TaskState::Blocked && t->interruptible) {
        wake_locked(t, -EINTR);
    } else if (t->state == TaskState::Suspended) {
        make_ready_locked(t);
    }
}

}  // namespace

bool hold_add_slow(void (*release)(void*, std::uint32_t), void* obj, std::uint32_t tag) {
    Tcb* t = caller();
    if (!t) return false;
    // An entry for the same object is stale (a lock is never held twice:
    // this one was given back where the task could not drop it, e.g. a
    // user spin-lock unlocked by another task): it goes, so such entries
    // never fill the list, and the new one is pushed as the newest.
    hold_drop_slow(obj);
    if (t->nholds == Tcb::kMaxHolds) return false;
    t->holds[t->nholds] = Tcb::Hold{release, obj, tag};
    // The entry is whole before the count shows it to a destroyer that
    // runs when this task is preempted (same thread).
    std::atomic_signal_fence(std::memory_order_release);
    ++t->nholds;
    return true;
}

void hold_drop_slow(void* obj) {
    Tcb* t = caller();
    if (!t) return;
    for (int i = t->nholds - 1; i >= 0; --i) {
        if (t->holds[i].obj != obj) continue;
        for (int j = i; j + 1 < t->nholds; ++j) t->holds[j] = t->holds[j + 1];
        std::atomic_signal_fence(std::memory_order_release);
        --t->nholds;
        return;
    }
}

void task_release_holds(Tcb* t) {
    // Newest first, each taken off before it runs: a release that faults
    // or ends the task is not run twice.
    for (;;) {
        Tcb::Hold h;
        {
            IrqGuard guard;
            if (!t->nholds) return;
            h = t->holds[--t->nholds];
        }
        h.release(h.obj, h.tag);
    }
}

void task_leave_calls_to(Tcb* t, unsigned holds, unsigned depth) {
    for (;;) {
        Tcb::Hold h;
        {
            IrqGuard guard;
            if (t->nholds <= holds) break;
            h = t->holds[--t->nholds];
        }
        h.release(h.obj, h.tag);
    }
    if (t->call_depth <= depth) return;
    t->call_depth = std::uint8_t(depth);
    t->at_cancel_point = false;
    if (depth) return;
    if (t->end_owed) task_end_current(CHM_TASK_DESTROYED, 0);
    if (t->abort_cycle_owed) {
        t->abort_cycle_owed = false;
        abort_cycle_current();
    }
}

bool task_owe_end_locked(Tcb* t) {
    if (!t->call_depth) return false;
    t->end_owed = true;
    if (t != g_k.current) cancel_wait_locked(t);
    else ++t->sigs_taken;
    return true;
}

void call_enter_slow() {
    if (Tcb* t = caller()) ++t->call_depth;
}

void call_leave_slow() {
    Tcb* t = caller();
    if (!t || !t->call_depth || --t->call_depth) return;
    if (t->end_owed) task_end_current(CHM_TASK_DESTROYED, 0);
    if (t->abort_cycle_owed) {
        t->abort_cycle_owed = false;
        abort_cycle_current();
        return;
    }
    IrqGuard guard;
    deliver_pending_locked();  // held back while the call ran
}

bool cancel_owed() {
    const Tcb* t = caller();
    return t && (t->end_owed || t->abort_cycle_owed);
}

void abort_cycle_current() {
    Tcb* t = caller();
    if (!t || !t->s.period_ns) return;
    if (t->call_depth) {
        t->abort_cycle_owed = true;
        ++t->sigs_taken;
        return;
    }
    port::irq_disable();
    t->abort_cycle = true;
    port::irq_restore();
    (void)chm_task_wait_period();  // restarts the entry at the next release
}

}  // namespace chm::kernel
