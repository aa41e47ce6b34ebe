// A task's life after spawn, for systems that start and stop tasks as a
// matter of course (reconfigurable modules): how a task ends (end hooks,
// task-local values, exit status), joining it, and changing its timing
// while it runs.
#include <cerrno>
#include <cstdlib>

#include "err/err_internal.hpp"
#include "kernel.hpp"

namespace chm::kernel {

namespace {
constexpr int kMaxHooks = 8;
constexpr std::uint32_t kMaxKeys = 32;
struct Hook {
    void (*fn)(void*);
    void* arg;
};
}  // namespace

// What only some tasks need, allocated on first use (a task that never
// registers a hook or a local value costs one null pointer).
struct TaskExt {
    Hook hooks[kMaxHooks];
    int nhooks;
    void* local[kMaxKeys];
};

namespace {

// Keys belong to the process (the RTPU) and outlive a kernel's teardown,
// like pthread keys.
void (*g_destructors[kMaxKeys])(void*) = {};
std::uint32_t g_nkeys = 0;

TaskExt* ext_locked(Tcb* t) {
    if (!t->ext) t->ext = static_cast<TaskExt*>(std::calloc(1, sizeof(TaskExt)));
    return t->ext;
}

}  // namespace

void task_run_end_hooks(Tcb* t) {
    // Most tasks hold nothing and registered nothing: no mask taken then.
    if (!t->nholds && !t->ext) return;
    task_release_holds(t);  // backplane locks and records first: others wait on them
    // Each hook is taken off the list before it runs: one that faults or
    // ends the task some other way is not run twice, and the rest still run
    // (the end that follows calls this again).
    for (;;) {
        Hook h;
        {
            IrqGuard guard;
            TaskExt* e = t->ext;
            if (!e || !e->nhooks) break;
            h = e->hooks[--e->nhooks];
        }
        h.fn(h.arg);
    }
    for (std::uint32_t k = 0; k < kMaxKeys; ++k) {
        void* v;
        void (*d)(void*);
        {
            IrqGuard guard;
            if (!t->ext) return;
            v = t->ext->local[k];
            t->ext->local[k] = nullptr;
            d = k < g_nkeys ? g_destructors[k] : nullptr;
        }
        if (v && d) d(v);
    }
}

[[noreturn]] void task_end_current(chm_task_end_reason reason, int status) {
    Tcb* cur = g_k.current;
    // Ending now: nothing is owed any more. An end hook's backplane call
    // (a state-variable set giving its claims back, say) must not carry
    // an owed end or cycle restart out again from inside the hook.
    cur->end_owed = false;
    cur->abort_cycle_owed = false;
    task_run_end_hooks(cur);
    port::irq_disable();
    cur->end_reason = std::uint8_t(reason);
    cur->exit_status = status;
    (void)port::call_indirect_return(task_switch_entry, cur, kSwitchEnd);  // never returns
    __builtin_unreachable();
}

void task_apply_timing_locked(Tcb* t) {
    // A task running on a lent timing (priority inheritance) takes its own
    // change when the loan ends, at a later release.
    if (!t->timing_pending || t->boosted) return;
    t->timing_pending = false;
    const chm_sched_task_t old = t->s;
    g_k.ops->retire(g_k.ops_self, &t->s);
    const chm_task_timing_t& n = t->new_timing;
    t->s.period_ns = n.period_ns;
    t->s.deadline_ns = n.deadline_ns;
    t->s.wcet_ns = n.wcet_ns;
    t->s.critical = n.critical;
    if (g_k.ops->admit(g_k.ops_self, &t->s) != 0) {  // a user scheduler refused it
        t->s.period_ns = old.period_ns;
        t->s.deadline_ns = old.deadline_ns;
        t->s.wcet_ns = old.wcet_ns;
        t->s.critical = old.critical;
        (void)g_k.ops->admit(g_k.ops_self, &t->s);
        ++t->timing_refused;
    }
}

}  // namespace chm::kernel

using namespace chm::kernel;
namespace port = chm::port;

extern "C" {

void chm_task_end(int status) {
    if (!g_k.current) return;  // not a task: nothing to end
    task_end_current(CHM_TASK_EXITED, status);
}

int chm_task_on_end(void (*hook)(void*), void* arg) {
    if (!hook) return raise_or_return(-EINVAL, "chm_task_on_end");
    IrqGuard guard;
    Tcb* cur = g_k.current;
    if (!cur) return raise_or_return(-EPERM, "chm_task_on_end");
    TaskExt* e = ext_locked(cur);
    if (!e) return raise_or_return(-ENOMEM, "chm_task_on_end");
    if (e->nhooks == kMaxHooks) return raise_or_return(-ENOSPC, "chm_task_on_end");
    e->hooks[e->nhooks++] = Hook{hook, arg};
    return 0;
}

int chm_task_key_create(chm_task_key_t* key, void (*destructor)(void*)) {
    if (!key) return raise_or_return(-EINVAL, "chm_task_key_create");
    IrqGuard guard;
    if (g_nkeys == kMaxKeys) return raise_or_return(-EAGAIN, "chm_task_key_create");
    g_destructors[g_nkeys] = destructor;
    *key = g_nkeys++;
    return 0;
}

void* chm_task_get_local(chm_task_key_t key) {
    Tcb* cur = g_k.current;  // only this task writes its own values
    return cur && cur->ext && key < kMaxKeys ? cur->ext->local[key] : nullptr;
}

int chm_task_set_local(chm_task_key_t key, void* value) {
    IrqGuard guard;
    if (key >= g_nkeys) return raise_or_return(-EINVAL, "chm_task_set_local");
    Tcb* cur = g_k.current;
    if (!cur) return raise_or_return(-EPERM, "chm_task_set_local");
    TaskExt* e = ext_locked(cur);
    if (!e) return raise_or_return(-ENOMEM, "chm_task_set_local");
    e->local[key] = value;
    return 0;
}

int chm_task_join(chm_tid_t id, uint64_t timeout_ns, chm_task_status_t* out) {
    IrqGuard guard;
    Tcb* cur = g_k.current;
    if (!cur) return raise_or_return(-EPERM, "chm_task_join");
    Tcb* t = tcb_lookup_ended_too(id);
    if (!t) return raise_or_return(-ESRCH, "chm_task_join");
    if (!t->joinable) return raise_or_return(-EINVAL, "chm_task_join");
    if (t == cur) return raise_or_return(-EDEADLK, "chm_task_join");
    if (t->joiners.head) return raise_or_return(-EBUSY, "chm_task_join");
    if (t->state != TaskState::Ended) {
        if (timeout_ns == CHM_NO_WAIT) return record_failure(-EAGAIN, "chm_task_join");  // an outcome, never raised
        cur->state = TaskState::Blocked;
        cur->interruptible = true;
        cur->wait_result = 0;
        waitq_insert_locked(&t->joiners, cur);
        if (timeout_ns != CHM_FOREVER) {
            cur->tmr.kind = TimerKind::Wake;
            const std::uint64_t now = now_locked();
            timer_add_locked(&cur->tmr, now + timeout_ns < now ? UINT64_MAX : now + timeout_ns);
            timer_program_locked(now);
        }
        const int r = block_current_locked();
        deliver_pending_locked();
        if (r != 0) return r;  // -ETIMEDOUT, -EINTR: outcomes, never raised
    }
    // A joinable task's slot is held for its joiner: `t` is still the task.
    if (out) (void)chm_task_status(id, out);
    t->joinable = false;
    t->joined = true;
    if (t->stack_gone) slot_release_locked(t);  // else freeing its stack will
    return 0;
}

int chm_task_set_timing(chm_tid_t id, const chm_task_timing_t* tm) {
    if (!tm) return raise_or_return(-EINVAL, "chm_task_set_timing");
    IrqGuard guard;
    Tcb* t = tcb_lookup(id);
    if (!t) return raise_or_return(-ESRCH, "chm_task_set_timing");
    const std::uint64_t own_period = t->boosted ? t->own.period_ns : t->s.period_ns;
    const std::uint64_t deadline = tm->deadline_ns ? tm->deadline_ns : tm->period_ns;
    if (!own_period || !tm->period_ns || deadline > tm->period_ns || tm->wcet_ns > deadline)
        return raise_or_return(-EINVAL, "chm_task_set_timing");
    t->new_timing = chm_task_timing_t{tm->period_ns, deadline, tm->wcet_ns, tm->critical ? 1 : 0};
    t->timing_pending = true;
    return 0;
}

}  // extern "C"
