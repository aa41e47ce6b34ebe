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

// Each table's `before` is the kernel's own comparison (sched/readyq.hpp),
// so a built-in table installed as a user scheduler orders exactly as the
// kernel's direct path does.
template <chm_sched_policy P>
int before(void*, const chm_sched_task_t* a, const chm_sched_task_t* b, std::uint64_t) {
    return key_before<P>(a, b);
}

// ---- shared queue operations over g_k.rq (keyed by the table's policy)
template <chm_sched_policy P>
void rq_enqueue(void*, chm_sched_task_t* t, std::uint64_t) {
    g_k.rq.push(tcb_of(t), rq_key<P>(t));
}
void rq_dequeue(void*, chm_sched_task_t* t) { g_k.rq.remove(tcb_of(t)); }
chm_sched_task_t* rq_pick(void*, std::uint64_t) {
    Tcb* t = g_k.rq.top();
    return t ? &t->s : nullptr;
}
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
    for (std::size_t i = 0; i < n && i < g_scratch_cap; ++i) g_scratch[i] = g_k.rq.at(i);
    const std::size_t m = n < g_scratch_cap ? n : g_scratch_cap;
    g_k.rq.clear();
    for (std::size_t i = 0; i < m; ++i) g_k.rq.push(g_scratch[i], rq_key<CHM_SCHED_MUF>(&g_scratch[i]->s));
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
    if (!g_k.rq.reserve(tasks, g_k.tcbs)) return false;
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
const chm_sched_ops_t chm_sched_muf_ops = {"muf", muf_admit, muf_retire,
                                           rq_enqueue<CHM_SCHED_MUF>, rq_dequeue, rq_pick,
                                           before<CHM_SCHED_MUF>, nullptr, nullptr};
const chm_sched_ops_t chm_sched_rm_ops = {"rm", admit_any, retire_any, rq_enqueue<CHM_SCHED_RM>,
                                          rq_dequeue, rq_pick, before<CHM_SCHED_RM>, nullptr,
                                          nullptr};
const chm_sched_ops_t chm_sched_edf_ops = {"edf", admit_any, retire_any,
                                           rq_enqueue<CHM_SCHED_EDF>, rq_dequeue, rq_pick,
                                           before<CHM_SCHED_EDF>, nullptr, nullptr};
const chm_sched_ops_t chm_sched_mlf_ops = {"mlf", admit_any, retire_any,
                                           rq_enqueue<CHM_SCHED_MLF>, rq_dequeue, rq_pick,
                                           before<CHM_SCHED_MLF>, nullptr, nullptr};
const chm_sched_ops_t chm_sched_fixed_ops = {"fixed", admit_any, retire_any,
                                             rq_enqueue<CHM_SCHED_FIXED>, rq_dequeue, rq_pick,
                                             before<CHM_SCHED_FIXED>, nullptr, nullptr};
}
