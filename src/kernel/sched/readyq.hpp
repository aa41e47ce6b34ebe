// The ready queue of the built-in policies and their ordering keys (MUF's
// own key, beside its critical set, is in sched/muf.hpp).
// Included by kernel.hpp (after Tcb); nothing here is public API.
//
// Why a key copied into the heap: a waiting task's order never changes
// while it waits (RM/FIXED keys are static, EDF's is the cycle's deadline,
// MLF/MUF's laxity key "deadline - remaining work" is constant for a task
// that does not run), so it is computed once at enqueue and the heap
// compares plain words in its own array. With 10,000 tasks a sift then
// touches the heap array and a dense slot table, not one TCB per level
// (which costs a cache miss each).
#pragma once

#include <cstddef>
#include <cstdint>

#include "chimera/kernel.h"
#include "chimera/sched.h"
#include "sched/muf.hpp"

namespace chm::kernel {

struct Tcb;

// Policy key, then user priority (higher first), then arrival (seq).
struct RqKey {
    std::uint64_t major = 0;
    std::uint64_t seq = 0;
    std::uint32_t minor = 0;
};

inline bool rq_key_less(const RqKey& a, const RqKey& b) {
    if (a.major != b.major) return a.major < b.major;
    if (a.minor != b.minor) return a.minor < b.minor;
    return a.seq < b.seq;
}

inline constexpr std::uint64_t kKeyNever = UINT64_MAX >> 1;  // 63 bits; MUF uses the top bit

inline std::uint64_t key63(std::uint64_t v) { return v < kKeyNever ? v : kKeyNever; }

// Laxity without the common "- now": deadline minus remaining work.
inline std::uint64_t lax_key(const chm_sched_task_t* t) {
    if (t->abs_deadline_ns == UINT64_MAX) return UINT64_MAX;
    const std::uint64_t rem = t->wcet_ns > t->cycle_cpu_ns ? t->wcet_ns - t->cycle_cpu_ns : 0;
    return t->abs_deadline_ns > rem ? t->abs_deadline_ns - rem : 0;
}

// The policy part of the order (smaller runs first). Times are clamped to
// 63 bits (292 years of ns): the same order for any real deadline.
template <chm_sched_policy P>
inline std::uint64_t major_key(const chm_sched_task_t* t) {
    if constexpr (P == CHM_SCHED_RM) return key63(t->period_ns ? t->period_ns : UINT64_MAX);
    else if constexpr (P == CHM_SCHED_EDF) return key63(t->abs_deadline_ns);
    else if constexpr (P == CHM_SCHED_MLF) return key63(lax_key(t));
    else if constexpr (P == CHM_SCHED_MUF)  // the critical set first, then laxity (sched/muf.hpp)
        return muf_major_key(t, key63(lax_key(t)));
    else return 0;  // FIXED: priority only
}

inline std::uint32_t minor_key(int priority) {
    return ~(std::uint32_t(priority) ^ 0x80000000u);  // higher priority -> smaller
}

template <chm_sched_policy P>
inline RqKey rq_key(const chm_sched_task_t* t) {
    return RqKey{major_key<P>(t), t->seq, minor_key(t->priority)};
}

// `before` of policy P: strictly more urgent (arrival does not count).
template <chm_sched_policy P>
inline bool key_before(const chm_sched_task_t* a, const chm_sched_task_t* b) {
    const std::uint64_t ma = major_key<P>(a), mb = major_key<P>(b);
    if (ma != mb) return ma < mb;
    return minor_key(a->priority) < minor_key(b->priority);
}

// The same for a policy known only at run time (a built-in one).
inline RqKey rq_key(chm_sched_policy p, const chm_sched_task_t* t) {
    switch (p) {
    case CHM_SCHED_RM: return rq_key<CHM_SCHED_RM>(t);
    case CHM_SCHED_EDF: return rq_key<CHM_SCHED_EDF>(t);
    case CHM_SCHED_MLF: return rq_key<CHM_SCHED_MLF>(t);
    case CHM_SCHED_MUF: return rq_key<CHM_SCHED_MUF>(t);
    default: return rq_key<CHM_SCHED_FIXED>(t);
    }
}
inline bool key_before(chm_sched_policy p, const chm_sched_task_t* a, const chm_sched_task_t* b) {
    switch (p) {
    case CHM_SCHED_RM: return key_before<CHM_SCHED_RM>(a, b);
    case CHM_SCHED_EDF: return key_before<CHM_SCHED_EDF>(a, b);
    case CHM_SCHED_MLF: return key_before<CHM_SCHED_MLF>(a, b);
    case CHM_SCHED_MUF: return key_before<CHM_SCHED_MUF>(a, b);
    default: return key_before<CHM_SCHED_FIXED>(a, b);
    }
}

// A binary min-heap of (key, TCB index); each task's heap slot lives in a
// dense table indexed by TCB index. O(log n) push and remove, O(1) top, and
// replace_top: the top leaves and another task enters in one sift (a yield
// or a preemption is one heap operation, not two). Storage grows only in
// reserve(), outside the interrupt mask.
class ReadyQueue {
public:
    bool reserve(std::size_t n, Tcb* base);
    void push(Tcb* t, const RqKey& k);
    void remove(Tcb* t);
    void replace_top(Tcb* t, const RqKey& k);
    Tcb* top() const;
    // The top sorts after `k` (size() > 0).
    bool top_after(const RqKey& k) const { return less(node(k, 0), nodes_[0]); }
    // The policy's `before` between the top and a task keyed `k`, arrival
    // ignored (size() > 0), from the key the top was queued with: it is
    // the key its view gives now (a waiting task's key is constant and
    // every change re-queues it), so the dispatcher computes one key per
    // decision instead of two.
    bool top_before(const RqKey& k) const { return less_by_policy(nodes_[0], node(k, 0)); }
    bool top_strictly_after(const RqKey& k) const { return less_by_policy(node(k, 0), nodes_[0]); }
    Tcb* at(std::size_t i) const;
    std::size_t size() const { return size_; }
    bool contains(const Tcb* t) const;
    void clear() { size_ = 0; }

private:
    struct Node {  // 24 bytes: the key's words and the TCB index
        std::uint64_t major, seq;
        std::uint32_t minor, idx;
    };
    static bool less(const Node& a, const Node& b) {
        if (a.major != b.major) return a.major < b.major;
        if (a.minor != b.minor) return a.minor < b.minor;
        return a.seq < b.seq;
    }
    static bool less_by_policy(const Node& a, const Node& b) {
        return a.major != b.major ? a.major < b.major : a.minor < b.minor;
    }
    static Node node(const RqKey& k, std::uint32_t idx) { return Node{k.major, k.seq, k.minor, idx}; }
    void sift_up(std::size_t i, Node x);
    void sift_down(std::size_t i, Node x);
    void place(std::size_t i, const Node& x) {
        nodes_[i] = x;
        slot_[x.idx] = std::int32_t(i);
    }
    Node* nodes_ = nullptr;
    std::int32_t* slot_ = nullptr;  // kMaxTasks entries, by TCB index
    Tcb* base_ = nullptr;
    std::size_t size_ = 0, cap_ = 0;
};

}  // namespace chm::kernel
