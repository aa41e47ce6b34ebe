// Local semaphores. The uncontended P and V are a few instructions under
// the cheap interrupt mask (seL4's lesson: guards first, then commit); only
// contention reaches the wait queue and the scheduler.
#include <cerrno>
#include <cstring>

#include "chimera/sem.h"
#include "kernel.hpp"

namespace chm::kernel {

namespace {

constexpr std::uint32_t kMagic = 0x53454d31;  // "SEM1"

struct Sem {
    std::uint32_t magic;
    std::uint32_t count;
    std::uint32_t max;
    std::uint32_t flags;
    WaitQueue waiters;
    Tcb* holder;  // binary + inherit: who took it last
    std::uint64_t reserved[2];
};
static_assert(sizeof(Sem) <= sizeof(chm_sem_t));

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

int p_slow_locked(Sem* m, std::uint64_t timeout_ns, bool timed) {
    Tcb* cur = g_k.current;
    if (!cur) return -EPERM;
    if (timed && timeout_ns == 0) return -ETIMEDOUT;
    cur->state = TaskState::Blocked;
    cur->interruptible = true;
    cur->wait_result = 0;
    waitq_insert_locked(&m->waiters, cur);
    if (m->flags & CHM_SEM_INHERIT) lend_locked(m);
    if (timed) {
        cur->tmr.kind = TimerKind::Wake;
        const std::uint64_t now = now_locked();
        timer_add_locked(&cur->tmr, now + timeout_ns);
        timer_program_locked(now);
    }
    const int r = block_current_locked();
    if (r == 0 && (m->flags & CHM_SEM_INHERIT)) m->holder = cur;
    deliver_pending_locked();
    return r;
}

int p_locked(chm_sem_t* s, std::uint64_t timeout_ns, bool timed, bool try_only) {
    Sem* m = as_sem(s);
    if (!m) return -EINVAL;
    if (m->count) [[likely]] {
        --m->count;
        if (m->flags & CHM_SEM_INHERIT) m->holder = g_k.current;
        return 0;
    }
    if (try_only) return -EAGAIN;
    return p_slow_locked(m, timeout_ns, timed);
}

}  // namespace

}  // namespace chm::kernel

using namespace chm::kernel;
namespace port = chm::port;

extern "C" {

int chm_sem_init(chm_sem_t* s, enum chm_sem_kind kind, uint32_t initial, uint32_t flags) {
    if (!s) return -EINVAL;
    if (kind != CHM_SEM_BINARY && kind != CHM_SEM_COUNTING) return -EINVAL;
    if (flags & ~CHM_SEM_INHERIT) return -EINVAL;
    if ((flags & CHM_SEM_INHERIT) && kind != CHM_SEM_BINARY) return -EINVAL;
    const std::uint32_t max = kind == CHM_SEM_BINARY ? 1 : CHM_SEM_COUNT_MAX;
    if (initial > max) return -EINVAL;
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
    if (!m) return -EINVAL;
    m->magic = 0;
    while (Tcb* t = m->waiters.head) wake_locked(t, -EIDRM);
    if (m->holder) unlend_locked(m->holder);
    reschedule_locked();
    return 0;
}

int chm_sem_p(chm_sem_t* s) {
    IrqGuard guard;
    return p_locked(s, 0, false, false);
}

int chm_sem_p_timed(chm_sem_t* s, uint64_t timeout_ns) {
    IrqGuard guard;
    return p_locked(s, timeout_ns, true, false);
}

int chm_sem_try_p(chm_sem_t* s) {
    IrqGuard guard;
    return p_locked(s, 0, false, true);
}

int chm_sem_v(chm_sem_t* s) {
    IrqGuard guard;
    Sem* m = as_sem(s);
    if (!m) return -EINVAL;
    if (m->flags & CHM_SEM_INHERIT) {
        if (m->holder) unlend_locked(m->holder);
        m->holder = nullptr;
    }
    Tcb* w = m->waiters.head;
    if (!w) [[likely]] {
        if (m->count >= m->max) return -EOVERFLOW;
        ++m->count;
        return 0;
    }
    // Hand the unit straight to the most urgent waiter.
    wake_locked(w, 0);
    reschedule_locked();
    return 0;
}

int chm_sem_value(const chm_sem_t* s) {
    const auto* m = reinterpret_cast<const Sem*>(s);
    return (s && m->magic == kMagic) ? int(m->count) : -EINVAL;
}

}  // extern "C"
