// The built-in policies' operations tables: each is one key over the same
// ready heap (Zephyr's lesson: the policy is a key, not a rewrite; the keys
// are in sched/readyq.hpp, MUF's beside its critical set in sched/muf.hpp
// and sched/muf.cpp). RM, EDF, MLF, MUF and fixed priority share enqueue,
// dequeue and pick. The kernel calls the same code directly when a
// built-in policy is in force.
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

}  // namespace

bool sched_reserve(std::size_t tasks) { return g_k.rq.reserve(tasks, g_k.tcbs); }

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
