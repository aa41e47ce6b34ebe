/* The pick-and-place demo's host programs (job.c, monitor.c): the module
 * instances, their RTPUs and rates, and the phases. */
#ifndef ARM_DEMO_HOST_H
#define ARM_DEMO_HOST_H

#include "arm.h"

enum { M_IO, M_GRAVITY, M_PD, M_TRAJ, M_FORCE, M_GRIPPER, M_COUNT };

typedef struct {
    const char* name;  /* instance name = the module's file name without .so */
    int rtpu;
    int period_mult;   /* period = period_mult x the base period */
    int critical;      /* its deadlines count in the outcome */
    int priority;
} demo_module_t;

/* Sensing first on RTPU 1 (highest priority), free-motion control beside
 * it; the trajectory, force control and the gripper on RTPU 2. */
static const demo_module_t demo_modules[M_COUNT] = {
    [M_IO] = {"arm_io", 1, 1, 1, 30},
    [M_GRAVITY] = {"gravity", 1, 1, 1, 20},
    [M_PD] = {"joint_pd", 1, 1, 1, 10},
    [M_TRAJ] = {"traj", 2, 1, 1, 20},
    [M_FORCE] = {"force_ctl", 2, 1, 1, 10},
    [M_GRIPPER] = {"gripper", 2, 5, 0, 5},
};

enum { PH_START = 1, PH_APPROACH, PH_PICK, PH_MOVE, PH_PLACE, PH_RETREAT, PH_STOP };
static const char* const demo_phase_names[] = {"setup", "start", "approach", "pick", "move", "place", "retreat", "stop"};

static inline const char* demo_phase_name(int p) {
    if (p == DEMO_DONE) return "done";
    return p >= 0 && p <= PH_STOP ? demo_phase_names[p] : "?";
}

#endif
