// The built-in policies: each is one `before` comparison over the same
// ready heap (Zephyr's lesson: the policy is a key, not a rewrite), plus the
// MUF critical set. RM, EDF, MLF, MUF and fixed priority share admit,
// enqueue, dequeue and pick.
#include <algorithm>
#include <cstdint>
#include <cstdlib>

#include "kernel.hpp"

namespace chm::kernel {

namespace {

constexpr std::uint64_t kNever = UINT64_MAX;
constexpr std::int32_t kInCriticalSet = 1;

// Laxity without the common "- now": deadline minus remaining work. Waiting
// tasks keep their key; only the running task's remaining work shrinks.
std::uint64_t lax_key(const chm_sched_task_t* t) {
    if (t->abs_deadline_ns == kNever) return kNever;
    const std::uint64_t rem = t->wcet_ns > t->cycle_cpu_ns ? t->wcet_ns - t->cycle_cpu_ns : 0;
    return t->abs_deadline_ns > rem ? t->abs_deadline_ns - rem : 0;
}

std::uint64_t rm_key(const chm_sched_task_t* t) { return t->period_ns ? t->period_ns : kNever; }

// Each returns <0 when a is more urgent, >0 when b is, 0 when equal.
template <class K>
int cmp(K a, K b) { return a < b ? -1 : (a > b ? 1 : 0); }

int by_priority(const chm_sched_task_t* a, const chm_sched_task_t* b) {
    return cmp(b->priority, a->priority);  // higher first
}

int fixed_before(void*, const chm_sched_task_t* a, const chm_sched_task_t* b, std::uint64_t) {
    return by_priority(a, b) < 0;
}

int rm_before(void*, const chm_sched_task_t* a, const chm_sched_task_t* b, std::uint64_t) {
    if (int c = cmp(rm_key(a), rm_key(b))) return c < 0;
    return by_priority(a, b) < 0;
}

int edf_before(void*, const chm_sched_task_t* a, const chm_sched_task_t* b, std::uint64_t) {
    if (int c = cmp(a->abs_deadline_ns, b->abs_deadline_ns)) return c < 0;
    return by_priority(a, b) < 0;
}

int mlf_before(void*, const chm_sched_task_t* a, const chm_sched_task_t* b, std::uint64_t) {
    if (int c = cmp(lax_key(a), lax_key(b))) return c < 0;
    return by_priority(a, b) < 0;
}

// MUF: criticality, then least laxity, then user priority (then arrival).
int muf_before(void*, const chm_sched_task_t* a, const chm_sched_task_t* b, std::uint64_t) {
    const int ca = a->flags & kInCriticalSet, cb = b->flags & kInCriticalSet;
    if (ca != cb) return ca > cb;
    if (int c = cmp(lax_key(a), lax_key(b))) return c < 0;
    return by_priority(a, b) < 0;
}

// ---- shared queue operations over g_k.rq
void rq_enqueue(void*, chm_sched_task_t* t, std::uint64_t now) {
    g_k.rq.less.now = now;
    g_k.rq.push(t);
}
void rq_dequeue(void*, chm_sched_task_t* t) { g_k.rq.remove(t); }
chm_sched_task_t* rq_pick(void*, std::uint64_t) { return g_k.rq.top(); }
int admit_any(void*, chm_sched_task_t* t) {
    t->flags = 0;
    return 0;
}
void retire_any(void*, chm_sched_task_t*) {}

// ---- MUF's critical set: user-marked tasks, then the periodic tasks in
// period order while the worst-case utilisation stays <= 1 (the longest
// such prefix). Recomputed on admission changes only, never per tick.
Tcb** g_scratch = nullptr;
std::size_t g_scratch_cap = 0;

void muf_recompute(Tcb* leaving) {
    std::size_t n = 0;
    for (std::uint32_t i = 0; i < g_k.tcb_hw; ++i) {
        Tcb* t = &g_k.tcbs[i];
        if (!t->used || t == leaving || t->state == TaskState::Ended) continue;
        t->s.flags &= ~kInCriticalSet;
        if (t->s.period_ns && n < g_scratch_cap) g_scratch[n++] = t;
    }
    // Utilisation in parts per billion to stay in integers.
    std::uint64_t util = 0;
    for (std::size_t i = 0; i < n; ++i) {
        Tcb* t = g_scratch[i];
        if (t->s.critical) {
            t->s.flags |= kInCriticalSet;
            util += t->s.wcet_ns * 1000000000ull / t->s.period_ns;
        }
    }
    std::sort(g_scratch, g_scratch + n, [](Tcb* a, Tcb* b) {
        if (a->s.period_ns != b->s.period_ns) return a->s.period_ns < b->s.period_ns;
        return a->s.seq < b->s.seq;
    });
    for (std::size_t i = 0; i < n; ++i) {
        Tcb* t = g_scratch[i];
        if (t->s.critical) continue;
        const std::uint64_t u = t->s.wcet_ns * 1000000000ull / t->s.period_ns;
        if (util + u > 1000000000ull) break;  // the prefix ends here
        util += u;
        t->s.flags |= kInCriticalSet;
    }
}

// The heap is keyed by the flags, so re-sort the ready tasks afterwards.
void muf_resort() {
    const std::size_t n = g_k.rq.size();
    for (std::size_t i = 0; i < n && i < g_scratch_cap; ++i) g_scratch[i] = tcb_of(g_k.rq.at(i));
    const std::size_t m = n < g_scratch_cap ? n : g_scratch_cap;
    for (std::size_t i = 0; i < m; ++i) g_k.rq.remove(&g_scratch[i]->s);
    for (std::size_t i = 0; i < m; ++i) g_k.rq.push(&g_scratch[i]->s);
}

int muf_admit(void*, chm_sched_task_t* t) {
    t->flags = 0;
    if (t->period_ns || t->critical) {
        muf_recompute(nullptr);
        if (t->critical && !t->period_ns) t->flags |= kInCriticalSet;
        muf_resort();
    }
    return 0;
}

void muf_retire(void*, chm_sched_task_t* t) {
    if (t->period_ns || t->critical) {
        muf_recompute(tcb_of(t));
        muf_resort();
    }
}

}  // namespace

bool sched_reserve(std::size_t tasks) {
    if (!g_k.rq.reserve(tasks)) return false;
    if (tasks > g_scratch_cap) {
        std::size_t cap = g_scratch_cap ? g_scratch_cap : 64;
        while (cap < tasks) cap *= 2;
        auto* p = static_cast<Tcb**>(std::realloc(g_scratch, cap * sizeof(Tcb*)));
        if (!p) return false;
        g_scratch = p;
        g_scratch_cap = cap;
    }
    return true;
}

}  // namespace chm::kernel

using namespace chm::kernel;

extern "C" {
const chm_sched_ops_t chm_sched_muf_ops = {"muf", muf_admit, muf_retire, rq_enqueue, rq_dequeue,
                                           rq_pick, muf_before, nullptr, nullptr};
const chm_sched_ops_t chm_sched_rm_ops = {"rm", admit_any, retire_any, rq_enqueue, rq_dequeue,
                                          rq_pick, rm_before, nullptr, nullptr};
const chm_sched_ops_t chm_sched_edf_ops = {"edf", admit_any, retire_any, rq_enqueue, rq_dequeue,
                                           rq_pick, edf_before, nullptr, nullptr};
const chm_sched_ops_t chm_sched_mlf_ops = {"mlf", admit_any, retire_any, rq_enqueue, rq_dequeue,
                                           rq_pick, mlf_before, nullptr, nullptr};
const chm_sched_ops_t chm_sched_fixed_ops = {"fixed", admit_any, retire_any, rq_enqueue,
                                             rq_dequeue, rq_pick, fixed_before, nullptr, nullptr};
}
