// Servo task control (chimera/servo.h, chimera/module.h): the express-mail
// requests between a controller and the RTPUs that host modules, and the
// RTPU side's interface (host.cpp, cycle.cpp, serve.cpp). The design is in
// docs/architecture.md, "Control modules and servo task control".
//
// Every request is one express-mail record of kind xmail::kServo: an Op
// word, then the op's fixed part, then its variable part. Fixed offsets on
// every target (m68k aligns 64-bit fields to 2 bytes, so each uint64_t
// sits at a multiple of 8 by construction). The RTPU decodes a copy of the
// request and checks every count and length against what it received.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>

#include "chimera/module.h"
#include "chimera/servo.h"
#include "chimera/svar.h"
#include "chimera/task.h"

namespace chm::servo {

enum Op : std::uint32_t {
    kTake = 1, kRelease, kSpawn, kFind, kPrepare, kCommit, kResolve, kControl, kClear, kKill, kStatus, kOutputs,
    kOpEnd
};

inline constexpr std::uint32_t kNameLen = 32;
inline constexpr std::uint32_t kSwitchMax = 16;  // modules of one switch on one RTPU
inline constexpr std::uint32_t kDisplaceMax = 32;
inline constexpr std::uint64_t kMinPeriodNs = 100'000;  // 10 kHz: the fastest module an RTPU runs

struct Ref {
    std::int32_t index;
    std::uint32_t gen;
};

struct SpawnReq {
    std::uint64_t period_ns, deadline_ns, wcet_ns;
    std::int32_t critical, priority, miss_policy;
    std::uint32_t n_params;
    char name[kNameLen];
    std::uint32_t path_len;  // bytes of the path after the params, NUL included
    std::uint32_t pad;
};
struct ParamOverride {
    char name[kNameLen];
    double value;
};
static_assert(sizeof(SpawnReq) == 80 && sizeof(ParamOverride) == 40);

struct FindReq {
    char name[kNameLen];
};

// kPrepare, kCommit, kResolve: then n Item, then n_displace names
// (prepare and commit: the modules going off; resolve: those going on).
struct SwitchReq {
    std::uint64_t at_ns;  // commit and resolve: T
    std::uint32_t n;
    std::uint32_t n_displace;
    std::uint32_t cell, seq;  // commit and resolve: the switch's decision cell (svar.hpp)
    std::uint32_t outcome;    // resolve: svar::kCellCommitted or kCellAborted
    std::uint32_t pad;
};
static_assert(sizeof(SwitchReq) == 32);
struct SwitchItem {
    Ref ref;
    std::uint32_t on;  // 1: going on; 0: going off at T; 2: going off when its outputs are taken at T
    std::uint32_t pad;
};

struct ControlReq {
    Ref ref;
    char name[kNameLen];
    double value;
};

struct StatusReply {
    char name[kNameLen];
    char module[kNameLen];
    std::int32_t state;
    std::uint32_t pad;
    std::uint64_t period_ns, cycles, misses, worst_ns, switched_at;
    std::uint64_t pending_at;  // the latest instant an earlier switch armed it for (0: none)
    char last_error[160];
};

// kOutputs reply: count, then count names.
struct OutputsReply {
    std::uint32_t count;
    std::uint32_t pad;
};

// ------------------------------------------------------------ RTPU side

// Serve one servo request (on the RTPU's express-mail server task).
// `from` is the sender's backplane token. The reply goes into rep (room
// bytes); on failure a NUL-terminated message follows any fixed reply.
int serve(const char* req, std::uint32_t len, char* rep, std::uint32_t room, std::uint32_t* n, std::uint32_t from);

}  // namespace chm::servo

// An instance, as module code sees it (chm_module_t) and the host keeps it.
// The first cache line holds what every cycle reads or writes (cycle.cpp):
// a cycle usually begins with cold caches, its task having slept a period,
// and each further line it touches is a miss.
struct alignas(64) chm_module {
    // ---- per cycle
    int (*cycle_fn)(chm_module_t*) = nullptr;  // desc->cycle: the descriptor is in another page
    chm_svar_set_t* set = nullptr;
    std::atomic<std::uint32_t> pending_mask{0};  // bit i: pending[i] waits for the next cycle
    // A module switched on: its cycle task and a resolve (aborted) race to
    // decide what happens to it, by CAS from kArmed.
    enum : int { kNotArmed = 0, kArmed, kActing, kCancelled };
    std::atomic<int> sw_arm{kNotArmed};
    // The cycle task stops at its first release >= the armed instant. Two
    // words, not a 64-bit atomic (m68k has none lock-free): the instant is
    // written while the flag is clear, and read only when it is set.
    std::atomic<std::uint32_t> off_armed{0};
    std::atomic<bool> missed_error{false};  // a miss under CHM_SERVO_MISS_ERROR
    // off_time was armed by a switch (not by kill/teardown): the module
    // stops there only if that switch was committed.
    std::atomic<bool> off_by_switch{false};
    std::uint64_t off_time = 0;
    std::uint64_t cycles = 0, release_now = 0;
    void arm_off(std::uint64_t t) {
        off_armed.store(0, std::memory_order_relaxed);
        std::atomic_signal_fence(std::memory_order_seq_cst);
        off_time = t;
        if (t) off_armed.store(1, std::memory_order_release);
    }
    std::uint64_t off_at() const { return off_armed.load(std::memory_order_acquire) ? off_time : 0; }

    // ---- the rest
    const chm_module_desc_t* desc = nullptr;
    bool used = false;
    std::uint32_t gen = 0;
    int index = 0;
    char name[chm::servo::kNameLen] = {};
    void* dl = nullptr;
    void* state_mem = nullptr;
    double params[CHM_MODULE_PARAMS_MAX] = {};
    double pending[CHM_MODULE_PARAMS_MAX] = {};
    std::uint64_t period_ns = 0, deadline_ns = 0, wcet_ns = 0;
    int critical = 0, priority = 0, miss_policy = 0;
    std::atomic<int> state{CHM_SERVO_NONE};
    std::uint64_t on_at = 0;                // committed first release
    // The switch that turns this module on, and the one that turns it off
    // (alone or handed over): its decision cell, and the outcome once known
    // here (0 until then), from the controller's resolve or read by the
    // module itself at T. Written by the server task before the cycle task
    // can look (it is armed after); a module may be in both at once (on at
    // T1, and already committed to go off at a later T2).
    struct SwitchSlot {
        std::atomic<std::uint32_t> cell{~0u}, seq{0}, outcome{0};
    };
    SwitchSlot on_sw, off_sw;
    chm_tid_t cycle_task = CHM_TID_NONE;
    bool cycle_done = false;                // the cycle task left its loop itself
    std::uint64_t misses = 0, worst_ns = 0, switched_at = 0;
    char last_error[160] = {};
};
static_assert(offsetof(chm_module, release_now) + sizeof(std::uint64_t) <= 64,
              "the per-cycle fields share one cache line");
