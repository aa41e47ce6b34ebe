// Simulated devices: the level-1 drivers (chimera/dev.h) that put each
// simulation behind the driver table, and what registry.cpp needs to
// create them.
#pragma once

#include <cstdint>

#include "chimera/dev.h"
#include "chimera/sensor.h"
#include "simfile.hpp"

namespace chm::sim {

// One registered simulated device (the `ctx` of its driver).
struct DevCtx {
    chm_sim_t* sim = nullptr;
    chm_sim_t* arm = nullptr;  // F/T sensor mounted on an arm
    // Serial port: the pseudo-terminal (master, and our own slave end kept
    // open so the master never sees a hang-up when the peer closes).
    int master = -1, slave = -1;
    std::int32_t timeout_ms = -1;
};

// One open descriptor (the `inst` of its driver).
struct Inst {
    DevCtx* ctx;
    int flags;
};

extern const chm_dev_ops_t kArmOps, kFtOps, kAdcOps, kSerialOps;

int generic_open(void* ctx, int flags, void** inst);
int generic_close(void* inst);

// Serial: open the pseudo-terminal and publish its other end (registry).
int serial_attach(DevCtx* c);
void serial_detach(DevCtx* c);

// Arm: bring the simulation up to date for an access from a driver
// (monotonic or kernel clock); state lock held. Returns true when the
// line must be raised (contact began).
bool arm_sync_locked(chm_sim_t* s);

// Copy helpers for level-2 descriptions.
void sio_set(chm_sio_info_t* info, std::uint32_t i, const char* name, const char* unit, double min,
             double max);

}  // namespace chm::sim
