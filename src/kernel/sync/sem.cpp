// Local semaphores. The uncontended P and V are a few instructions under
// the cheap interrupt mask (seL4's lesson: guards first, then commit); only
// contention reaches the wait queue and the scheduler.
#include <cerrno>
#include <cstring>

#include "chimera/sem.h"
#include "err/err_internal.hpp"
#include "kernel.hpp"

namespace chm::kernel {

namespace {

constexpr std::uint32_t kMagic = 0x53454d31;  // "SEM1"
// In flags: its holder was aborted; the next P that takes it reports
// -EOWNERDEAD (err/, owner-died semantics).
constexpr std::uint32_t kOwnerDied = 0x80000000u;

struct Sem {
    std::uint32_t magic;
    std::uint32_t count;
    std::uint32_t max;
    std::uint32_t flags;
    WaitQueue waiters;
    Tcb* holder;  // binary: who took it and has not given it back
    // The binary semaphores a task holds, linked from Tcb::held, so that
    // an aborted task's are released (owner-died semantics).
    Sem* hnext;
    Sem* hprev;
};
static_assert(sizeof(Sem) <= sizeof(chm_sem_t));

// A binary semaphore changes hands: unlink it from its holder's list and
// link it to `t` (nullptr: nobody holds it).
void hold_locked(Sem* m, Tcb* t) {
    if (Tcb* h = m->holder) {
        if (m->hprev) m->hprev->hnext = m->hnext;
        else h->held = m->hnext;
        if (m->hnext) m->hnext->hprev = m->hprev;
    }
    m->holder = t;
    if (t) {
        m->hprev = nullptr;
        m->hnext = static_cast<Sem*>(t->held);
        if (m->hnext) m->hnext->hprev = m;
        t->held = m;
    }
}

// A successful P of a binary semaphore: take it; report a dead owner once.
int took_binary_locked(Sem* m, Tcb* t) {
    hold_locked(m, t);
    if (m->flags & kOwnerDied) [[unlikely]] {
        m->flags &= ~kOwnerDied;
        return -EOWNERDEAD;
    }
    return 0;
}

Sem* as_sem(chm_sem_t* s) {
    auto* m = reinterpret_cast<Sem*>(s);
    return (s && m->magic == kMagic) ? m : nullptr;
}

// Priority inheritance: the holder takes the urgency of the waiter at the
// head while it is more urgent than itself.
void lend_locked(Sem* m) {
    Tcb* h = m->holder;
    Tcb* w = m->waiters.head;
    if (!h || !w || h->state == TaskState::Ended) return;
    const std::uint64_t now = now_locked();
    if (!sched_before_locked(w, h, now)) return;
    const bool queued = h->in_ready;
    if (queued) unready_locked(h);
    if (!h->boosted) {
        h->own = h->s;
        h->boosted = true;
    }
    h->s.priority = w->s.priority;
    h->s.critical = w->s.critical;
    h->s.flags = w->s.flags;
    h->s.abs_deadline_ns = w->s.abs_deadline_ns;
    h->s.wcet_ns = w->s.wcet_ns > w->s.cycle_cpu_ns ? w->s.wcet_ns - w->s.cycle_cpu_ns + h->s.cycle_cpu_ns : h->s.cycle_cpu_ns;
    h->s.period_ns = w->s.period_ns;
    if (queued) make_ready_locked(h, true);
}

void unlend_locked(Tcb* h) {
    if (!h->boosted) return;
    const bool queued = h->in_ready;
    if (queued) unready_locked(h);  // its heap key is about to change
    h->boosted = false;
    h->s.priority = h->own.priority;
    h->s.critical = h->own.critical;
    h->s.flags = h->own.flags;
    h->s.abs_deadline_ns = h->own.abs_deadline_ns;
    h->s.wcet_ns = h->own.wcet_ns;
    h->s.period_ns = h->own.period_ns;
    if (queued) make_ready_locked(h, true);
}

// How long a P may wait (chimera/kernel.h, "Timeouts"): not at all
// (try_p, CHM_NO_WAIT: -EAGAIN), a relative timeout, or an absolute
// deadline on the kernel clock (chm_time_now(); exact on the virtual
// clock: the wake-up timer is armed at the deadline itself). CHM_FOREVER
// in either form means no limit.
enum class Limit { kNone, kTry, kRelative, kAbsolute };

int p_slow_locked(Sem* m, Limit limit, std::uint64_t t) {
    Tcb* cur = g_k.current;
    if (!cur) return -EPERM;
    std::uint64_t deadline = CHM_FOREVER;
    if (limit != Limit::kNone && t != CHM_FOREVER) {
        const std::uint64_t now = now_locked();
        deadline = limit == Limit::kAbsolute ? t : (now + t < now ? CHM_FOREVER : now + t);
        if (deadline <= now) return -ETIMEDOUT;  // a deadline already past: no wait
    }
    cur->state = TaskState::Blocked;
    cur->interruptible = true;
    cur->wait_result = 0;
    waitq_insert_locked(&m->waiters, cur);
    if (m->flags & CHM_SEM_INHERIT) lend_locked(m);
    if (deadline != CHM_FOREVER) {
        cur->tmr.kind = TimerKind::Wake;
        timer_add_locked(&cur->tmr, deadline);
        timer_program_locked(now_cached_locked());
    }
    int r = block_current_locked();
    if (r == 0 && m->max == 1) r = took_binary_locked(m, cur);
    else if (r == -EOWNERDEAD) hold_locked(m, cur);  // handed over by an aborted holder
    deliver_pending_locked();
    return r;
}

// A P that finds a unit (count > 0) takes it.
int take_unit_locked(Sem* m) {
    --m->count;
    return m->max == 1 ? took_binary_locked(m, g_k.current) : 0;
}

// A V of a binary semaphore: its holder gives it up (and a loan with it).
void give_up_hold_locked(Sem* m) {
    if (m->max != 1) return;
    if ((m->flags & CHM_SEM_INHERIT) && m->holder) unlend_locked(m->holder);
    hold_locked(m, nullptr);
}

int p_locked(chm_sem_t* s, Limit limit, std::uint64_t t) {
    Sem* m = as_sem(s);
    if (!m) return -EINVAL;
    if (m->count) [[likely]] return take_unit_locked(m);
    if (limit == Limit::kTry || (limit == Limit::kRelative && t == CHM_NO_WAIT)) return -EAGAIN;
    return p_slow_locked(m, limit, t);
}

// chm_sem_p and chm_sem_v in one function, with one call of the
// scheduler for both a P that blocks and a V that wakes. A V that wakes a
// more urgent task switches to it inside that call, and the woken task
// resumes inside the same call where its P blocked: every return level
// between the switch and this function is then the same in both tasks,
// which the return predictor gets right (with two functions, each level
// of the woken task's return was mispredicted: ~38 ns for the V-wake
// switch, docs/architecture.md "Yield and the switch"). The public calls
// reach it through port::call_indirect_return, whose indirect jump to the
// caller the branch-history steering predicts. Only the calls that may
// switch come here: a P that finds a unit and a V that finds no waiter
// stay in chm_sem_p / chm_sem_v and return plainly (through the
// trampoline, P and V called in turn alternated its one indirect jump
// between two callers with the same history: a P + V pair 4 -> 16 ns).
// Behaviour is exactly that of p_locked (no limit) and of the old V.
enum : std::uintptr_t { kOpP = 0, kOpV = 1 };

// What sem_step_locked did: its status so far, and whether the scheduler
// must run (a V woke a waiter; a P blocked: `wait`, its result is the
// waker's).
struct SemStep {
    Sem* m;
    int r;
    bool sched, wait;
};

// Everything before the scheduler. Not inlined: its result is opaque to
// sem_pv, so the compiler keeps one call of the scheduler there instead
// of threading each case into a call of its own.
__attribute__((noinline)) SemStep sem_step_locked(void* sem, std::uintptr_t op) {
    Sem* m = as_sem(static_cast<chm_sem_t*>(sem));
    Tcb* cur = g_k.current;
    SemStep st{m, 0, false, false};
    // The callers kept the cases that cannot switch (mask held since): a
    // V comes here with a waiter, a P with no unit left.
    if (!m) {
        st.r = -EINVAL;
    } else if (op == kOpV) {
        give_up_hold_locked(m);
        wake_locked(m->waiters.head, 0);  // hand the unit straight to the most urgent waiter
        st.sched = cur && !g_k.in_irq;
    } else if (cur && !g_k.in_irq && !(m->flags & CHM_SEM_INHERIT)) {
        // p_slow_locked's block with no limit, no inheritance, not in an
        // interrupt handler (block_current_locked's refusal).
        cur->state = TaskState::Blocked;
        cur->interruptible = true;
        cur->wait_result = 0;
        waitq_insert_locked(&m->waiters, cur);
        st.sched = st.wait = true;
    } else {
        st.r = p_slow_locked(m, Limit::kNone, 0);
    }
    return st;
}

// Entered with the mask held (chm_sem_p, chm_sem_v); releases it.
int sem_pv(void* sem, std::uintptr_t op) {
    SemStep st = sem_step_locked(sem, op);
    if (st.sched) schedule_locked();
    if (st.wait) {
        Tcb* cur = g_k.current;
        st.r = cur->wait_result;
        if (st.r == 0 && st.m->max == 1) st.r = took_binary_locked(st.m, cur);
        else if (st.r == -EOWNERDEAD) hold_locked(st.m, cur);  // handed over by an aborted holder
    }
    if (st.sched) deliver_pending_locked();
    st.r = raise_or_return(st.r, op == kOpV ? "chm_sem_v" : "chm_sem_p");  // with the mask held, as before
    port::irq_restore();
    return st.r;
}

}  // namespace

void sem_release_held_locked(Tcb* t, bool owner_died) {
    while (Sem* m = static_cast<Sem*>(t->held)) {
        hold_locked(m, nullptr);
        if (!owner_died || m->magic != kMagic) continue;
        // Give it back as V would, telling the next taker its owner died.
        if (Tcb* w = m->waiters.head) {
            wake_locked(w, -EOWNERDEAD);
        } else {
            m->flags |= kOwnerDied;
            if (m->count < m->max) ++m->count;
        }
    }
}

}  // namespace chm::kernel

using namespace chm::kernel;
namespace port = chm::port;

extern "C" {

int chm_sem_init(chm_sem_t* s, enum chm_sem_kind kind, uint32_t initial, uint32_t flags) {
    const std::uint32_t max = kind == CHM_SEM_BINARY ? 1 : CHM_SEM_COUNT_MAX;
    if (!s || (kind != CHM_SEM_BINARY && kind != CHM_SEM_COUNTING) || (flags & ~CHM_SEM_INHERIT) ||
        ((flags & CHM_SEM_INHERIT) && kind != CHM_SEM_BINARY) || initial > max)
        return raise_or_return(-EINVAL, "chm_sem_init");
    std::memset(s, 0, sizeof *s);
    auto* m = reinterpret_cast<Sem*>(s);
    m->count = initial;
    m->max = max;
    m->flags = flags;
    m->magic = kMagic;
    return 0;
}

int chm_sem_destroy(chm_sem_t* s) {
    IrqGuard guard;
    Sem* m = as_sem(s);
    if (!m) return raise_or_return(-EINVAL, "chm_sem_destroy");
    m->magic = 0;
    while (Tcb* t = m->waiters.head) wake_locked(t, -EIDRM);
    if (m->holder) unlend_locked(m->holder);
    hold_locked(m, nullptr);
    reschedule_locked();
    return 0;
}

int chm_sem_p(chm_sem_t* s) {
    port::irq_disable();
    Sem* m = as_sem(s);
    if (m && m->count) [[likely]] {
        const int r = raise_or_return(take_unit_locked(m), "chm_sem_p");
        port::irq_restore();
        return r;
    }
    return port::call_indirect_return(sem_pv, s, kOpP);  // the mask held: sem_pv releases it
}

int chm_sem_p_timed(chm_sem_t* s, uint64_t timeout_ns) {
    IrqGuard guard;
    return raise_or_return(p_locked(s, Limit::kRelative, timeout_ns), "chm_sem_p_timed");
}

int chm_sem_p_until(chm_sem_t* s, uint64_t deadline_ns) {
    IrqGuard guard;
    return raise_or_return(p_locked(s, Limit::kAbsolute, deadline_ns), "chm_sem_p_until");
}

int chm_sem_try_p(chm_sem_t* s) {
    IrqGuard guard;
    return raise_or_return(p_locked(s, Limit::kTry, 0), "chm_sem_try_p");
}

int chm_sem_v(chm_sem_t* s) {
    port::irq_disable();
    Sem* m = as_sem(s);
    if (m && !m->waiters.head) [[likely]] {
        give_up_hold_locked(m);
        int r = 0;
        if (m->count >= m->max) r = -EOVERFLOW;  // returned, not raised
        else ++m->count;
        port::irq_restore();
        return r;
    }
    return port::call_indirect_return(sem_pv, s, kOpV);  // the mask held: sem_pv releases it
}

int chm_sem_value(const chm_sem_t* s) {
    const auto* m = reinterpret_cast<const Sem*>(s);
    return (s && m->magic == kMagic) ? int(m->count) : -EINVAL;
}

}  // extern "C"
