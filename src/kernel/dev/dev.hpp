// Device drivers, internal: the driver table, the descriptor slots and the
// one place where a failing device call is reported. Level 1 (table.cpp)
// and level 2 (sensor.cpp) share them; nothing here is public API.
#pragma once

#include <pthread.h>

#include <cstdarg>
#include <cstdint>

#include "chimera/dev.h"
#include "chimera/sensor.h"

namespace chm::dev {

struct Driver {
    bool used = false;
    char name[CHM_DEV_NAME_MAX + 1] = {};
    const chm_dev_ops_t* ops = nullptr;
    void* ctx = nullptr;
    std::uint32_t open_count = 0;  // slots (open or closing) on this driver
};

struct Mapping {
    void* addr = nullptr;
    std::size_t len = 0;
};
inline constexpr int kMaxMappings = 8;

struct Actuator;  // level-2 state of a descriptor (sensor.cpp)

enum class SlotState : std::uint8_t { Free, Opening, Open, Closing };

// One descriptor. `gen` is bumped at close, so a stale descriptor no longer
// matches; `refs` counts the open reference plus calls in progress, and the
// driver's close runs when it drops to zero.
struct Slot {
    SlotState state = SlotState::Free;
    std::uint32_t gen = 0;
    std::uint32_t refs = 0;
    int driver = -1;
    void* inst = nullptr;
    std::uint64_t range = 0;
    std::uint64_t pos = 0;
    int flags = 0;
    chm_tid_t owner = CHM_TID_NONE;
    Mapping maps[kMaxMappings];
    Actuator* act = nullptr;
};

// A call in progress on a descriptor: validates it, pins the slot (the
// driver's close waits for us) and, on the kernel thread, holds the
// interrupt mask for the duration so the driver is never preempted half way.
class Use {
public:
    Use(int dd, const char* call);
    ~Use();
    Use(const Use&) = delete;
    Use& operator=(const Use&) = delete;
    bool ok() const { return status == 0; }
    int status = 0;       // 0 or the refusal (already reported)
    Slot* slot = nullptr;
    const chm_dev_ops_t* ops = nullptr;
    const char* name = "";
    int dd = -1;
    const char* call;

private:
    bool masked_ = false;
};

// The reporting point: records "call: device: problem" for
// chm_dev_last_error() and returns `status`. When the global error layer
// exists, this is where it raises the error signal.
int fail(int status, const char* call, const char* fmt, ...) __attribute__((format(printf, 3, 4)));

// The exit of every public call: a status that fail() reported becomes an
// error signal of module "dev" when the calling task has global error
// handling on (chimera/err.h) and holds no lock; then it is returned.
// Outcomes (-EAGAIN, -ETIMEDOUT, -EINTR) and positive reports are only
// returned.
int64_t leave(int64_t status);

// chm_dev_open / chm_dev_close without the error signal (level 2 uses
// them and raises once, at its own exit).
int open_quiet(const char* name, int flags);
int close_quiet(int dd);

// Level 2 hooks used by level 1 at close and at task abort.
void actuator_stop_for_close(Slot* s, const chm_dev_ops_t* ops);  // safe stop if an actuator
void actuator_free(Actuator* a);

// Attach level-2 state to an open descriptor; false when it is not open.
bool attach_actuator(int dd, Actuator* a);

// Copy up to `max` open descriptors into `out`: all of them (any_owner) or
// those of `owner`, optionally only actuators. Returns how many.
int list_open(int* out, int max, bool any_owner, chm_tid_t owner, bool actuators_only);

}  // namespace chm::dev
