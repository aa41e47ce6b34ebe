// Task management: the TCB array, spawn, exit, destroy, suspend, resume,
// static priority, lookup and status.
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <new>
#include <sys/mman.h>

#include "err/err_internal.hpp"
#include "core/fiber_asan.hpp"
#include "kernel.hpp"
#include "lib/hot.hpp"

namespace chm::kernel {

namespace {

constexpr std::size_t kMinStackBytes = 8 * 1024;

bool tcbs_reserved() {
    if (g_k.tcbs) return true;
    // Reserved once; pages are committed as slots are first used.
    void* m = mmap(nullptr, sizeof(Tcb) * kMaxTasks, PROT_READ | PROT_WRITE,
                   MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
    if (m == MAP_FAILED) return false;
    g_k.tcbs = static_cast<Tcb*>(m);
    return true;
}

Tcb* slot_take_locked() {
    std::uint32_t i;
    if (g_k.cold_slot >= 0) {
        i = std::uint32_t(g_k.cold_slot);
        g_k.cold_slot = g_k.tcbs[i].next_free;
    } else if (g_k.free_slot >= 0) {
        i = std::uint32_t(g_k.free_slot);
        g_k.free_slot = g_k.tcbs[i].next_free;
        if (g_k.free_slot < 0) g_k.free_tail = -1;
        --g_k.free_recent;
    } else if (g_k.tcb_hw < kMaxTasks) {
        i = g_k.tcb_hw++;
    } else {
        return nullptr;
    }
    Tcb* t = &g_k.tcbs[i];
    const std::uint64_t gen = t->gen;  // 0 for a slot never used
    new (t) Tcb;  // default-initialised: the fields valid only under a flag are left (kernel.hpp)
    t->gen = gen + 1;  // never wraps: slot_release_locked retires a slot at kGenMax
    t->index = i;
    t->short_id = tid_short(tid_of(t));  // no 64-bit division per switch
    t->used = true;
    t->tmr.owner = t->dl.owner = t;
    t->tmr.kind = TimerKind::Wake;
    t->dl.kind = TimerKind::Deadline;
    return t;
}

}  // namespace

// An ended task's final status stays readable (chm_task_status) until its
// slot is taken again, and a freed slot is not taken while kSlotRetain
// slots freed after it are still free: the recently freed wait in order,
// oldest first, and a spawn takes one of them only when no older slot is
// free. The older ones are taken newest first, so a system that spawns
// and ends tasks all the time keeps reusing the same few TCBs, hot in the
// cache. (Oldest-freed first over every free slot kept a status readable
// longer, but once a burst of 10,000 tasks had ended, each later spawn
// took a TCB not touched since: spawn + run + exit 112 -> ~240 ns.)
void slot_release_locked(Tcb* t) {
    t->used = false;
    t->next_free = -1;
    // Its last generation used: the slot is retired, so no id repeats. At
    // one spawn per 145 ns on this one slot that is 236 days; the table
    // runs out after 32,768 times as many spawns (~21,000 years).
    if (t->gen >= kGenMax) {
        ++g_k.slots_retired;
        return;
    }
    const std::int32_t i = std::int32_t(t->index);
    if (g_k.free_tail >= 0) g_k.tcbs[g_k.free_tail].next_free = i;
    else g_k.free_slot = i;
    g_k.free_tail = i;
    if (++g_k.free_recent <= kSlotRetain) return;
    // The oldest of the recently freed has waited through kSlotRetain later ends.
    const std::int32_t old = g_k.free_slot;
    g_k.free_slot = g_k.tcbs[old].next_free;
    --g_k.free_recent;
    g_k.tcbs[old].next_free = g_k.cold_slot;
    g_k.cold_slot = old;
}

namespace {

int check_attr(const chm_task_attr_t& a, std::size_t* stack) {
    *stack = a.stack_size ? a.stack_size : g_k.cfg.default_stack;
    if (*stack < kMinStackBytes) return -EINVAL;
    if (a.name && std::strlen(a.name) > CHM_TASK_NAME_MAX) return -ENAMETOOLONG;
    if (a.period_ns) {
        if (a.deadline_ns > a.period_ns) return -EINVAL;     // deadline beyond period
        if (a.wcet_ns > (a.deadline_ns ? a.deadline_ns : a.period_ns)) return -EINVAL;
    } else if (a.deadline_ns || a.start_ns) {
        return -EINVAL;  // deadlines and releases need a period
    }
    return 0;
}

// Zero-padded (status copies it whole); check_attr bounded its length.
// The default name is one constant copy, not a strncpy call per spawn.
void copy_name(char (&to)[CHM_TASK_NAME_MAX + 1], const char* name) {
    static constexpr char kDefault[CHM_TASK_NAME_MAX + 1] = "task";
    if (!name) {
        std::memcpy(to, kDefault, sizeof to);
        return;
    }
    const std::size_t n = strnlen(name, sizeof to - 1);
    std::memcpy(to, name, n);
    std::memset(to + n, 0, sizeof to - n);
}

}  // namespace

Tcb* tcb_lookup(chm_tid_t id) {
    Tcb* t = tcb_lookup_ended_too(id);
    return t && t->used && t->state != TaskState::Ended ? t : nullptr;
}

// A task that ended keeps its TCB (state Ended, generation) until the slot
// is taken again: its final counters stay readable.
Tcb* tcb_lookup_ended_too(chm_tid_t id) {
    if (id < 0 || !g_k.tcbs) return nullptr;
    const std::uint32_t i = std::uint32_t(id & 0xffff);
    if (i >= g_k.tcb_hw) return nullptr;
    Tcb* t = &g_k.tcbs[i];
    if (t->gen != (std::uint64_t(id) >> 16)) return nullptr;
    return (t->used || t->state == TaskState::Ended) && !t->joined ? t : nullptr;
}

bool tcb_view_valid(const chm_sched_task_t* s) {
    const auto p = reinterpret_cast<std::uintptr_t>(s);
    const auto base = reinterpret_cast<std::uintptr_t>(g_k.tcbs) + offsetof(Tcb, s);
    if (!g_k.tcbs || p < base) return false;
    const std::uintptr_t off = p - base;
    if (off % sizeof(Tcb) != 0 || off / sizeof(Tcb) >= g_k.tcb_hw) return false;
    const Tcb* t = &g_k.tcbs[off / sizeof(Tcb)];
    return t->used && t->state != TaskState::Ended;
}

void task_start(void* p) {
    asan::switch_end(nullptr);  // the first time on this stack
    Tcb* t = static_cast<Tcb*>(p);
    errno = 0;
    if (Tcb* z = g_k.zombie; z && z != t) {
        g_k.zombie = nullptr;
        task_free_stack_locked(z);
    }
    // The context that switched here held the mask (every switch happens at
    // nest == 1); it is ours to release, then take what is owed to us.
    deliver_pending_locked();
    port::irq_restore();
    t->entry(t->arg);
    task_end_current(CHM_TASK_RETURNED, 0);
}

namespace {

// Everything of task_switch_entry before the scheduler, and the clock
// reading it runs at. Not inlined: its result is opaque to the entry, so
// the scheduler keeps one call site there.
__attribute__((noinline)) std::uint64_t switch_step_locked(void* tcb, std::uintptr_t op) {
    if (op == kSwitchSpawn) {
        // The spawn's own reading (now_locked, moments ago) is the switch's.
        const std::uint64_t now = now_cached_locked();
        if (g_k.cfg.cpu_accounting) charge_current_locked(now);
        return now;
    }
    Tcb* cur = static_cast<Tcb*>(tcb);
    task_end_locked(cur);
    if (g_k.zombie) task_free_stack_locked(g_k.zombie);  // not yet reaped (we ran without returning from a switch)
    g_k.zombie = cur;
    return schedule_now_locked();
}

}  // namespace

CHM_HOT int task_switch_entry(void* tcb, std::uintptr_t op) {
    schedule_at_locked(switch_step_locked(tcb, op));
    deliver_pending_locked();  // the spawner's, once it runs again
    port::irq_restore();
    return 0;
}

CHM_HOT void release_cycle_locked(Tcb* t, std::uint64_t release) {
    task_apply_timing_locked(t);  // chm_task_set_timing takes effect here
    // Counted here, not when the task returns from its wait: a deadline
    // that passes before it runs again names the cycle that missed.
    t->cycle = t->releases++;
    t->s.release_ns = release;
    t->s.abs_deadline_ns = release + t->s.deadline_ns;
    t->s.cycle_cpu_ns = 0;
    t->awaiting_release = false;
    t->release_pending = false;
    // A cycle that completes exactly at its deadline is on time: the miss
    // fires only once the deadline has passed.
    timer_add_locked(&t->dl, t->s.abs_deadline_ns + 1);
    if (g_k.ops->release) g_k.ops->release(g_k.ops_self, &t->s, release);
}

void task_end_locked(Tcb* t) {
    err_task_ended_locked(t);
    unready_locked(t);
    waitq_remove_locked(t);
    timer_cancel_locked(&t->tmr);
    timer_cancel_locked(&t->dl);
    g_k.ops->retire(g_k.ops_self, &t->s);
    if (!t->end_reason) t->end_reason = CHM_TASK_DESTROYED;
    t->state = TaskState::Ended;
    --g_k.alive;
    while (Tcb* j = t->joiners.head) wake_locked(j, 0);
    if (t->ext) {  // its hooks and local values were run already
        std::free(t->ext);
        t->ext = nullptr;
    }
}

void task_free_stack_locked(Tcb* t) {
    asan::stack_fresh(t->stack_lo, t->stack_size);  // its frames are gone: scanned and zeroed next
    t->final_high_water = stack_scrub(t);
    stacks_release(t->stack_lo, t->stack_size);
    t->stack_lo = nullptr;
    t->stack_gone = true;
    if (!t->joinable) slot_release_locked(t);  // a joinable task's waits for chm_task_join
}

}  // namespace chm::kernel

using namespace chm::kernel;
namespace port = chm::port;

extern "C" {

void chm_task_attr_init(chm_task_attr_t* a) {
    if (a) *a = chm_task_attr_t{};
}

}  // extern "C"

namespace {

// The spawn proper, mask held: 0 and the new task in *made, or the error
// (raised or returned as chm_task_spawn's).
int spawn_locked(chm_tid_t* out, void (*entry)(void*), void* arg, const chm_task_attr_t& a, std::size_t stack,
                 Tcb** made) {
    if (!tcbs_reserved() || !sched_reserve(g_k.alive + 1) || !g_k.timers.reserve(2 * (g_k.alive + 1)))
        return raise_or_return(-ENOMEM, "chm_task_spawn");
    unsigned char* lo;
    if (int e = stacks_reserve(stack, &lo)) return raise_or_return(e, "chm_task_spawn");
    Tcb* t = slot_take_locked();
    if (!t) {
        stacks_release(lo, stack);
        return record_failure(-EAGAIN, "chm_task_spawn");
    }
    t->stack_lo = lo;
    t->stack_size = stack;
    t->entry = entry;
    t->arg = arg;
    copy_name(t->name, a.name);
    t->s.id = tid_of(t);
    t->s.priority = a.priority;
    t->s.critical = a.critical;
    t->s.period_ns = a.period_ns;
    t->s.deadline_ns = a.period_ns ? (a.deadline_ns ? a.deadline_ns : a.period_ns) : 0;
    t->s.wcet_ns = a.wcet_ns;
    t->s.abs_deadline_ns = UINT64_MAX;
    t->s.slot = -1;
    t->on_deadline = a.on_deadline;
    t->on_deadline_arg = a.on_deadline_arg;
    t->handler_priority = a.handler_priority;
    t->joinable = a.joinable != 0;
    asan::stack_fresh(lo, stack);
    port::context_init(&t->ctx, lo, stack, task_start, t);
    if (int e = g_k.ops->admit(g_k.ops_self, &t->s)) {
        stacks_release(lo, stack);
        slot_release_locked(t);
        return e < 0 ? e : -EAGAIN;
    }
    ++g_k.alive;
    const std::uint64_t now = now_locked();  // the switch below runs at this reading too
    if (a.period_ns) {
        const std::uint64_t first = a.start_ns ? a.start_ns : now;
        if (first > now) {
            t->state = TaskState::WaitPeriod;
            t->tmr.kind = TimerKind::Release;
            timer_add_locked(&t->tmr, first);
            timer_program_locked(now);
        } else {
            release_cycle_locked(t, first);
            make_ready_locked(t);
        }
    } else {
        make_ready_locked(t);
    }
    if (out) *out = tid_of(t);
    *made = t;
    return 0;
}

}  // namespace

extern "C" {

int chm_task_spawn(chm_tid_t* out, void (*entry)(void*), void* arg, const chm_task_attr_t* attr) {
    if (!g_k.initialised) return raise_or_return(-EPERM, "chm_task_spawn");
    if (!entry) return raise_or_return(-EINVAL, "chm_task_spawn");
    chm_task_attr_t a{};
    if (attr) a = *attr;
    std::size_t stack;
    if (int e = check_attr(a, &stack)) return raise_or_return(e, "chm_task_spawn");
    stack = stack_round(stack);

    port::irq_disable();
    Tcb* t = nullptr;
    const int e = spawn_locked(out, entry, arg, a, stack, &t);
    // The new task may be more urgent than its parent: from a task, the
    // switch goes through task_switch_entry (which releases the mask).
    if (e || !g_k.current || g_k.in_irq) {
        if (!e) reschedule_at_locked(now_cached_locked());  // not from a task: no switch here
        port::irq_restore();
        return e;
    }
    return port::call_indirect_return(task_switch_entry, t, kSwitchSpawn);
}

void chm_task_exit(void) {
    if (!g_k.current) return;  // not a task: nothing sensible to end
    task_end_current(CHM_TASK_EXITED, 0);
}

int chm_task_destroy(chm_tid_t id) {
    Tcb* t;
    {
        IrqGuard guard;
        t = tcb_lookup(id);
        if (!t) return raise_or_return(-ESRCH, "chm_task_destroy");
        // Inside a backplane call: it ends when the call returns or
        // reaches its wait (task/holds.hpp), never with an object locked.
        if (task_owe_end_locked(t)) {
            if (t != g_k.current) reschedule_locked();
            return 0;
        }
        if (t == g_k.current) {
            port::irq_restore();
            task_end_current(CHM_TASK_EXITED, 0);
        }
        // Off the CPU for good before its hooks run in our context: a
        // suspended task stays off whatever wakes it meanwhile.
        ++t->suspend_count;
        if (t->state == TaskState::Ready) {
            unready_locked(t);
            t->state = TaskState::Suspended;
        }
    }
    task_run_end_hooks(t);  // its holds, then hooks (only its own calls make those)
    IrqGuard guard;
    if (tid_of(t) == id && t->state != TaskState::Ended) {  // nobody ended it meanwhile
        t->end_reason = CHM_TASK_DESTROYED;
        const bool joined = t->joiners.head != nullptr;
        task_end_locked(t);
        task_free_stack_locked(t);
        if (joined) reschedule_locked();  // its joiner may be more urgent than we are
    }
    return 0;
}

int chm_task_suspend(chm_tid_t id) {
    IrqGuard guard;
    Tcb* t = tcb_lookup(id);
    if (!t) return raise_or_return(-ESRCH, "chm_task_suspend");
    ++t->suspend_count;
    if (t->state == TaskState::Ready) {
        unready_locked(t);
        t->state = TaskState::Suspended;
    } else if (t->state == TaskState::Running) {
        t->state = TaskState::Suspended;
        reschedule_locked();
    }
    return 0;
}

int chm_task_resume(chm_tid_t id) {
    IrqGuard guard;
    Tcb* t = tcb_lookup(id);
    if (!t) return raise_or_return(-ESRCH, "chm_task_resume");
    if (!t->suspend_count) return raise_or_return(-EINVAL, "chm_task_resume");
    if (--t->suspend_count == 0 && t->state == TaskState::Suspended) {
        make_ready_locked(t);
        reschedule_locked();
    }
    return 0;
}

int chm_task_set_priority(chm_tid_t id, int priority) {
    IrqGuard guard;
    Tcb* t = tcb_lookup(id);
    if (!t) return raise_or_return(-ESRCH, "chm_task_set_priority");
    if (t->boosted) {
        t->own.priority = priority;  // takes effect when the loan ends
        return 0;
    }
    const bool queued = t->in_ready;
    if (queued) unready_locked(t);
    t->s.priority = priority;
    if (queued) {
        t->in_ready = true;
        sched_enqueue_locked(t);
    }
    if (t->wq) {  // re-sort it among the waiters
        WaitQueue* q = t->wq;
        waitq_remove_locked(t);
        waitq_insert_locked(q, t);
    }
    reschedule_locked();
    return 0;
}

chm_tid_t chm_task_self(void) {
    Tcb* cur = g_k.current;
    return cur ? tid_of(cur) : CHM_TID_NONE;
}

int chm_task_find(const char* name, chm_tid_t* out) {
    if (!name || !out) return record_failure(-EINVAL, "chm_task_find");
    IrqGuard guard;
    for (std::uint32_t i = 0; i < g_k.tcb_hw; ++i) {
        Tcb* t = &g_k.tcbs[i];
        if (t->used && t->state != TaskState::Ended && std::strcmp(t->name, name) == 0) {
            *out = tid_of(t);
            return 0;
        }
    }
    return record_failure(-ESRCH, "chm_task_find");
}

int chm_task_count(void) { return int(g_k.alive); }

int chm_task_status(chm_tid_t id, chm_task_status_t* out) {
    if (!out) return raise_or_return(-EINVAL, "chm_task_status");
    IrqGuard guard;
    Tcb* t = tcb_lookup_ended_too(id);
    if (!t) return raise_or_return(-ESRCH, "chm_task_status");
    if (t == g_k.current) charge_current_locked(now_locked());
    *out = chm_task_status_t{};
    out->id = id;
    std::memcpy(out->name, t->name, sizeof out->name);
    switch (t->state) {
    case TaskState::Ready: out->state = CHM_TASK_READY; break;
    case TaskState::Running: out->state = CHM_TASK_RUNNING; break;
    case TaskState::Blocked: out->state = CHM_TASK_BLOCKED; break;
    case TaskState::Suspended: out->state = CHM_TASK_SUSPENDED; break;
    case TaskState::WaitPeriod: out->state = CHM_TASK_WAITING_PERIOD; break;
    case TaskState::Paused: out->state = CHM_TASK_PAUSED; break;
    case TaskState::Ended: out->state = CHM_TASK_ENDED; break;
    }
    const chm_sched_task_t& v = t->boosted ? t->own : t->s;
    out->priority = v.priority;
    out->critical = (t->s.flags & 1) || t->s.critical;
    out->period_ns = t->s.period_ns;
    out->deadline_ns = t->s.deadline_ns;
    out->wcet_ns = t->s.wcet_ns;
    out->cpu_ns = t->cpu_ns;
    out->cycles = t->cycles_done;
    out->misses = t->misses;
    out->worst_lateness_ns = t->worst_lateness;
    out->worst_cycle_cpu_ns = t->worst_cycle_cpu;
    out->stack_size = t->stack_size;
    out->stack_high_water = t->stack_lo ? stack_high_water(t) : t->final_high_water;
    out->end_reason = t->state == TaskState::Ended ? chm_task_end_reason(t->end_reason) : CHM_TASK_LIVE;
    out->exit_status = t->exit_status;
    out->timing_refused = t->timing_refused;
    return 0;
}

}  // extern "C"
