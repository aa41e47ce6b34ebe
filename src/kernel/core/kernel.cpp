// The kernel's life: init on the kernel thread, the run loop (which is also
// the idle context), graceful stop with shutdown hooks, and teardown.
#include <cerrno>
#include <cstring>
#include <sys/mman.h>

#include "err/err_internal.hpp"
#include "core/fiber_asan.hpp"
#include "kernel.hpp"
#include "mem/mem_text.hpp"
#include "task/holds.hpp"
#include "kernel/mem/heap.hpp"
#include "sync/remote_wait.hpp"
#include "lib/hot.hpp"

namespace chm::kernel {

void dispatch_install_hooks();
void programs_unload_all();
port::TickHandler dispatch_tick_handler();

namespace {

// The heap serves every thread; on the kernel thread its lock is also held
// under the interrupt mask, so no task is ever preempted holding it.
// The heap lock's hooks run inside a malloc that libc may have made with
// its own locks held: in the allocator's section, whose code is never
// preempted, and calling nothing out of it while the mask is free
// (mem/mem_text.hpp).
CHM_MEM_TEXT void heap_enter() {
    if (port::on_kernel_thread()) port::irq_disable();
}
CHM_MEM_TEXT void heap_leave() {
    // Never switch here: libc may have called malloc holding its own locks.
    if (port::on_kernel_thread()) port::irq_restore_no_switch();
}

void run_shutdown_hooks() {
    while (g_k.nhooks > 0) {
        const Kernel::Hook h = g_k.hooks[--g_k.nhooks];
        h.fn(h.arg);
    }
}

// The idle loop: runs in chm_kernel_run's context with the mask held,
// dispatches whenever something is ready and otherwise sleeps.
CHM_HOT __attribute__((noinline)) int idle_loop_locked() {
    for (;;) {
        if (g_k.stopping) return g_k.stop_code;
        if (g_k.alive == 0) return 0;
        const std::uint64_t now = now_locked();
        irq_dispatch_locked();
        if (g_k.cfg.virtual_clock) timers_run_locked(now);
        Tcb* head = sched_pick_locked(now);
        if (head) {
            g_k.idle_poll_spent = false;  // it was for the last wait only
            if (io_watching_locked()) io_busy_arm_locked(now);
            schedule_locked();  // switches to it; returns when idle again
            continue;
        }
        if (io_watching_locked()) {
            io_idle_wait_locked();  // real time passes, also on the virtual clock
            continue;
        }
        if (g_k.cfg.virtual_clock) {
            const std::uint64_t due = next_due_locked();
            if (!due) return -EDEADLK;  // every task waits for ever
            if (due > g_k.vnow) g_k.vnow = due;  // idle time passes at once
            continue;
        }
        timer_program_locked(now);
        // A task that spun out its wait before it parked did this poll.
        const std::uint64_t poll_ns = g_k.idle_poll_spent ? 0 : g_k.cfg.idle_poll_ns;
        g_k.idle_poll_spent = false;
        if (poll_ns && remote_waiting_locked()) {
            // The poll watches the parked tasks' words: a grant needs no ring.
            port::idle_wait_locked(poll_ns, &kRemoteWatch);
            remote_scan_locked();
        } else if (!idle_lead_wait_locked(now, poll_ns)) {
            port::idle_wait_locked(poll_ns);
        }
        // A ring marked pending is dispatched at the top of the loop.
        if (port::irq_take_pending_bits() & port::kPendingTick) idle_tick_locked();
    }
}

}  // namespace

}  // namespace chm::kernel

using namespace chm::kernel;
namespace port = chm::port;

extern "C" {

void chm_kernel_config_init(chm_kernel_config_t* cfg) {
    if (!cfg) return;
    *cfg = chm_kernel_config_t{};
    cfg->policy = CHM_SCHED_MUF;
    cfg->quantum_ns = 1000000;
    cfg->default_stack = 64 * 1024;
    cfg->rtpu_id = 1;
    cfg->cpu_accounting = 1;
    cfg->io_poll_ns = 1000000;
    cfg->timer_lead_ns = CHM_TIMER_LEAD_AUTO;
}

int chm_kernel_init(const chm_kernel_config_t* cfg) {
    if (g_k.initialised) return record_failure(-EBUSY, "chm_kernel_init");
    chm_kernel_config_t c;
    chm_kernel_config_init(&c);
    if (cfg) c = *cfg;
    if (c.quantum_ns && c.quantum_ns < 10000) return record_failure(-EINVAL, "chm_kernel_init");
    if (!c.io_poll_ns) c.io_poll_ns = 1000000;
    if (c.io_poll_ns < 10000) return record_failure(-EINVAL, "chm_kernel_init");
    if (c.timer_lead_ns < CHM_TIMER_LEAD_AUTO || c.timer_lead_ns > kLeadMaxNs)
        return record_failure(-EINVAL, "chm_kernel_init");
    if (!c.default_stack) c.default_stack = 64 * 1024;
    if (int e = sched_select(c.policy, c.user_sched, c.user_sched_arg)) return e;
    g_k.cfg = c;
    timer_lead_reset_locked();
    g_k.switch_timed = c.cpu_accounting || c.quantum_ns;
    g_k.vnow = 0;
    if (!c.virtual_clock) {
        dispatch_install_hooks();
        if (int e = port::timer_init(dispatch_tick_handler())) return e;
        chm_heap_set_lock_hooks(heap_enter, heap_leave);
        // libc calls malloc with its own locks held: a task must never be
        // switched out anywhere in the allocator (hooks and PLT included).
        const chm::mem::CodeRange alloc = chm::mem::allocator_code_range();
        if (alloc.lo < alloc.hi) {
            port::irq_disable();
            port::preemptible_range_exclude(alloc.lo, alloc.hi);
            // Its calls into the C library, where they go through PLT entries in
            // the object's own text (m68k: no -fno-plt). Unreadable file:
            // the entries stay preemptible, as before.
            (void)port::preemptible_exclude_plt(reinterpret_cast<const void*>(alloc.lo));
            port::irq_restore();
        }
    } else {
        port::irq_set_pending_hook(nullptr);
        port::set_kernel_thread(true);
    }
    if (int e = err_kernel_init()) return e;  // processor exceptions (err/fault.cpp)
    g_k.initialised = true;
    g_tasks_exist.store(true, std::memory_order_relaxed);  // backplane calls now track tasks' holds (task/holds.hpp)
    return 0;
}

int chm_kernel_run(void) {
    if (!g_k.initialised || g_k.current) return record_failure(-EPERM, "chm_kernel_run");
    port::irq_disable();
    g_k.errno_loc = &errno;  // tasks run on this thread only
    g_k.running = true;
    const int r = idle_loop_locked();
    g_k.running = false;
    if (!g_k.cfg.virtual_clock && port::timer_interval()) {  // no ticks for a stopped kernel
        port::timer_arm_locked(0);
        g_k.armed_at = 0;
    }
    port::irq_restore();
    return r;
}

void chm_kernel_stop(int code) {
    port::irq_disable();
    if (g_k.stop_requested && !g_k.stopping && g_k.current && g_k.current == g_k.hooks_runner) {
        port::irq_restore();  // from a shutdown hook: the stop is under way already
        return;
    }
    if (!g_k.stop_requested) {
        g_k.stop_requested = true;
        g_k.stop_code = code;
        g_k.hooks_runner = g_k.current;
        port::irq_restore();
        // In the caller's context, the other tasks still running: a hook
        // may block (pause, wait for a task to finish its cycle). The run
        // loop returns only once they are done.
        run_shutdown_hooks();
        port::irq_disable();
        g_k.stopping = true;
    }
    // Leave for the run loop; the tasks stay as they are until fini.
    Tcb* cur = g_k.current;
    if (cur) {
        unready_locked(cur);
        cur->state = TaskState::Suspended;
        ++cur->suspend_count;
        g_k.current = nullptr;
        g_k.quantum_due = 0;  // its slice ends here: no tick for it
        g_k.quantum_lazy = false;
        port::Context* from = &cur->ctx;
        void* asan_save = nullptr;
        asan::switch_begin(&asan_save, nullptr, 0);
        port::context_switch(from, &g_k.idle_ctx);
        asan::switch_end(asan_save);
    }
    port::irq_restore();
}

int chm_kernel_on_shutdown(void (*hook)(void*), void* arg) {
    if (!hook) return record_failure(-EINVAL, "chm_kernel_on_shutdown");
    IrqGuard guard;
    if (g_k.nhooks >= 32) return record_failure(-ENOSPC, "chm_kernel_on_shutdown");
    g_k.hooks[g_k.nhooks++] = Kernel::Hook{hook, arg};
    return 0;
}

void chm_kernel_fini(void) {
    if (!g_k.initialised || g_k.running) return;
    // The tasks still there end with the kernel: their hooks first, in the
    // kernel thread's context (no current task).
    for (std::uint32_t i = 0; i < g_k.tcb_hw; ++i) {
        Tcb* t = &g_k.tcbs[i];
        if (t->used && t->state != TaskState::Ended) task_run_end_hooks(t);
    }
    port::irq_disable();
    for (std::uint32_t i = 0; i < g_k.tcb_hw; ++i) {
        Tcb* t = &g_k.tcbs[i];
        if (!t->used) continue;
        if (t->state != TaskState::Ended) task_end_locked(t);
        if (t->stack_lo) task_free_stack_locked(t);
    }
    g_k.zombie = nullptr;
    port::irq_restore();
    programs_unload_all();
    if (!g_k.cfg.virtual_clock) {
        chm_heap_set_lock_hooks(nullptr, nullptr);
        port::timer_fini();
    } else {
        port::set_kernel_thread(false);
    }
    port::irq_set_pending_hook(nullptr);
    port::chm_port_preempt_hook = nullptr;
    irq_reset();
    err_kernel_fini();
    // Keep the reserved TCB array and the heaps' storage for a next init;
    // reset everything else.
    Tcb* tcbs = g_k.tcbs;
    const std::uint32_t hw = g_k.tcb_hw;
    ReadyQueue rq = g_k.rq;
    TimerHeap timers = g_k.timers;
    rq.clear();
    while (timers.size()) timers.remove(timers.top());
    g_k = Kernel{};
    g_k.tcbs = tcbs;
    g_k.rq = rq;
    g_k.timers = timers;
    // Slots keep their generation so stale ids never match a new task;
    // retired ones (kGenMax) stay off the free list.
    g_k.tcb_hw = hw;
    for (std::uint32_t i = 0; i < hw; ++i) {
        tcbs[i].used = false;
        slot_release_locked(&tcbs[i]);  // in slot order, as before
    }
}

}  // extern "C"
