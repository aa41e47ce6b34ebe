/* The pick-and-place demo (make demo): the arm's geometry and the scene,
 * the names of the state variables the modules share, and the kinematics
 * and gravity model the modules and the host programs use (static inline:
 * every module is its own shared object).
 *
 * The arm: two 0.5 m, 1 kg links in the vertical x-z plane (the simulator's
 * defaults), a gripper at the tip; a surface at z = ARM_SURFACE_Z; an
 * object of 0.2 kg on it at x = ARM_OBJECT_X, to be put down at
 * x = ARM_TARGET_X. */
#ifndef ARM_DEMO_H
#define ARM_DEMO_H

#include <math.h>

#define ARM_L1 0.5
#define ARM_L2 0.5
#define ARM_M1 1.0
#define ARM_M2 1.0
#define ARM_C1 0.25 /* centres of mass from each joint */
#define ARM_C2 0.25
#define ARM_G 9.81
#define ARM_SURFACE_Z (-0.30)
#define ARM_OBJECT_X 0.65
#define ARM_OBJECT_MASS 0.2
#define ARM_TARGET_X 0.35
#define ARM_HOME_X 0.45
#define ARM_HOME_Z 0.0

/* State variables (doubles unless noted; vectors of 2 are per joint, or
 * x and z). Written by: */
#define SV_Q "arm_q"           /* arm_io: joint angles, rad */
#define SV_QD "arm_qd"         /* arm_io: joint rates, rad/s */
#define SV_F "arm_f"           /* arm_io: F/T sensor, contact force on the tip (Fx, Fz), N */
#define SV_GRIP "arm_grip"     /* arm_io: jaw opening (m), squeeze (N) */
#define SV_OBJ "arm_obj"       /* arm_io: the object (x, z, held 0/1), from the simulator */
#define SV_T "arm_t"           /* arm_io: the arm's time, s (0: no sample yet) */
#define SV_TAU "arm_tau"       /* joint_pd or force_ctl: joint torques, N*m */
#define SV_TAU_G "arm_tau_g"   /* gravity: the torques that hold the arm up, N*m */
#define SV_Q_REF "arm_q_ref"   /* traj: reference joint angles, rad */
#define SV_QD_REF "arm_qd_ref" /* traj: reference joint rates, rad/s */
#define SV_X_REF "arm_x_ref"   /* traj: the reference's tip position (x, z), m */
#define SV_GRIP_CMD "arm_grip_cmd" /* gripper: commanded jaw opening, m (scalar) */
#define SV_PHASE "demo_phase"  /* the job (int32): phase number, DEMO_DONE at the end */
#define SV_SWITCHES "demo_switches" /* the job: DEMO_SW_MAX x 4: T (s, CLOCK_MONOTONIC),
                                     * cycles from request to T, cycles missed by
                                     * the switched modules, phase */
#define DEMO_SW_MAX 8
#define DEMO_DONE 99

/* Tip position of joint angles q. */
static inline void arm_fk(const double q[2], double x[2]) {
    x[0] = ARM_L1 * cos(q[0]) + ARM_L2 * cos(q[0] + q[1]);
    x[1] = ARM_L1 * sin(q[0]) + ARM_L2 * sin(q[0] + q[1]);
}

/* The tip's Jacobian J (row-major 2x2): xdot = J qd, tau = J^T F. */
static inline void arm_jacobian(const double q[2], double j[4]) {
    const double s1 = sin(q[0]), c1 = cos(q[0]), s12 = sin(q[0] + q[1]), c12 = cos(q[0] + q[1]);
    j[0] = -ARM_L1 * s1 - ARM_L2 * s12;
    j[1] = -ARM_L2 * s12;
    j[2] = ARM_L1 * c1 + ARM_L2 * c12;
    j[3] = ARM_L2 * c12;
}

/* Joint angles putting the tip at x (elbow up). 0, or -1 out of reach. */
static inline int arm_ik(const double x[2], double q[2]) {
    const double c2 = (x[0] * x[0] + x[1] * x[1] - ARM_L1 * ARM_L1 - ARM_L2 * ARM_L2) / (2 * ARM_L1 * ARM_L2);
    if (!(c2 > -1.0 && c2 < 1.0)) return -1;
    q[1] = -acos(c2);
    q[0] = atan2(x[1], x[0]) - atan2(ARM_L2 * sin(q[1]), ARM_L1 + ARM_L2 * cos(q[1]));
    return 0;
}

/* The joint torques that hold the arm at q against gravity, with a point
 * mass `payload` (kg) in the jaws. */
static inline void arm_gravity(const double q[2], double payload, double tau[2]) {
    tau[1] = ARM_G * (ARM_M2 * ARM_C2 + payload * ARM_L2) * cos(q[0] + q[1]);
    tau[0] = ARM_G * (ARM_M1 * ARM_C1 + (ARM_M2 + payload) * ARM_L1) * cos(q[0]) + tau[1];
}

#endif
