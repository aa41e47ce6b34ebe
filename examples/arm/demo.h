/* The pick-and-place demo's host programs (job.c, monitor.c): the modules
 * the phases switch, and the phases. */
#ifndef ARM_DEMO_HOST_H
#define ARM_DEMO_HOST_H

#include "arm.h"

/* The modules the phases switch, by their names in system.toml (which
 * also says where and how fast each runs). */
enum { M_IO, M_GRAVITY, M_PD, M_TRAJ, M_FORCE, M_GRIPPER, M_COUNT };
static const char* const demo_module_names[M_COUNT] = {
    [M_IO] = "arm_io",   [M_GRAVITY] = "gravity",  [M_PD] = "joint_pd",
    [M_TRAJ] = "traj",   [M_FORCE] = "force_ctl",  [M_GRIPPER] = "gripper",
};

enum { PH_START = 1, PH_APPROACH, PH_PICK, PH_MOVE, PH_PLACE, PH_RETREAT, PH_STOP };
static const char* const demo_phase_names[] = {"setup", "start", "approach", "pick", "move", "place", "retreat", "stop"};

static inline const char* demo_phase_name(int p) {
    if (p == DEMO_DONE) return "done";
    return p >= 0 && p <= PH_STOP ? demo_phase_names[p] : "?";
}

#endif
