// MUF, maximum-urgency-first (Stewart & Khosla), Chimera II's default
// policy: its ordering key and its critical set's data. The set itself is
// kept by sched/muf.cpp (admit, retire); the key is read by the ready
// queue's compare on the hot path (sched/readyq.hpp includes this header),
// so it stays inline here. Nothing here is public API.
#pragma once

#include <cstdint>

#include "chimera/sched.h"

namespace chm::kernel {

struct Tcb;

// chm_sched_task_t::flags: the task is in MUF's critical set.
inline constexpr std::int32_t kInCriticalSet = 1;

// MUF's policy key (smaller runs first): the critical set first (top bit
// clear), then laxity; `lax63` is the task's laxity key clamped to 63 bits
// (readyq.hpp: key63(lax_key(t))).
inline std::uint64_t muf_major_key(const chm_sched_task_t* t, std::uint64_t lax63) {
    return ((t->flags & kInCriticalSet) ? 0 : (1ull << 63)) | lax63;
}

// A task's place in MUF's rate-ordered set of non-critical periodic tasks
// (sched/muf.cpp), or the utilisation it adds to the critical tasks'.
struct MufNode {
    Tcb* left = nullptr;
    Tcb* right = nullptr;
    Tcb* parent = nullptr;
    std::uint64_t period = 0, order = 0, util = 0, sum = 0, crit_util = 0;
    std::uint32_t prio = 0;
    bool in_tree = false;
};
struct MufSet {
    Tcb* root = nullptr;
    Tcb* boundary = nullptr;  // first task outside the critical prefix; nullptr: all in
    std::uint64_t crit_util = 0, order = 0;
    std::uint32_t rng = 2463534242u;
};

// MUF's admit and retire (sched/muf.cpp): keep the critical set.
int muf_admit(void* self, chm_sched_task_t* t);
void muf_retire(void* self, chm_sched_task_t* t);

}  // namespace chm::kernel
