/* Chimera simulated devices: a robot arm with 1 to 6 joints, a
 * force/torque sensor with a contact surface, an A/D and D/A converter and
 * a serial port on a pseudo-terminal.
 *
 * Each device keeps its state in a shared-memory file (by default under
 * chm_sim_dir()) so any process can drive or watch it: the RTPU that
 * registers it as a level-1/level-2 device (chm_sim_register), a test, or a
 * person with the chimera-sim tool. Every file has a companion FIFO
 * "<file>.irq" that becomes readable when the device raises its line (new
 * A/D input, contact onset, a manual step, a safe stop): that is what an
 * interrupt handler attaches to (CHM_DEV_IOC_EVENT_FD).
 *
 * Functions return 0 or a negative errno-style status. */
#ifndef CHIMERA_SIM_H
#define CHIMERA_SIM_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

enum chm_sim_kind { CHM_SIM_ARM = 1, CHM_SIM_FT = 2, CHM_SIM_ADC = 3, CHM_SIM_SERIAL = 4 };

/* How a simulated device's time advances. */
enum chm_sim_clock {
    CHM_SIM_CLOCK_MONOTONIC = 0, /* to CLOCK_MONOTONIC on every access, by any
                                  * process, in fixed steps (deterministic in
                                  * the elapsed time) */
    CHM_SIM_CLOCK_MANUAL = 1,    /* only by chm_sim_arm_step (tests) */
    CHM_SIM_CLOCK_KERNEL = 2     /* to chm_time_now() of the registering RTPU
                                  * (its virtual clock in virtual-clock mode);
                                  * other processes only watch */
};

/* What a safe stop does to the arm. */
enum chm_sim_stop_mode {
    CHM_SIM_STOP_ZERO_TORQUE = 0, /* amplifiers off: torque 0, the arm coasts */
    CHM_SIM_STOP_HOLD = 1         /* brakes: the joints are held where they are */
};

#define CHM_SIM_PATH_MAX 200

/* The directory of simulated devices: $CHIMERA_SIM_DIR, or
 * /dev/shm/chimera-sim-<uid> (created, mode 0700). */
const char* chm_sim_dir(void);

/* A file name without '/' names a file in chm_sim_dir(); anything else is
 * used as given. Errors: -ENAMETOOLONG, -EINVAL. */
int chm_sim_path(const char* name_or_path, char* out, size_t cap);

/* An attached shared-state file. */
typedef struct chm_sim chm_sim_t;

/* Map a device's file. Errors: -ENOENT; -EPROTO not a simulated-device file
 * of this version; -errno of open/mmap. */
int chm_sim_attach(const char* path, chm_sim_t** out);
void chm_sim_detach(chm_sim_t* sim);
enum chm_sim_kind chm_sim_kind_of(const chm_sim_t* sim);
/* Changes so far (bumped at every change of the state; watchers poll it). */
uint64_t chm_sim_seq(const chm_sim_t* sim);
/* Remove a device's file and its FIFO. Errors: -ENOENT. */
int chm_sim_remove(const char* path);

/* Register the device in `path` (a file of any kind) in this RTPU's driver
 * table under `devname`; a serial port gets its pseudo-terminal here.
 * Errors: those of chm_sim_attach and chm_dev_register. */
int chm_sim_register(const char* devname, const char* path);
/* Register every device file in `dir` (NULL: chm_sim_dir()) under its file
 * name. Returns how many were registered, or -errno of opendir. */
int chm_sim_register_dir(const char* dir);
/* Unregister (and free the simulation's driver state). Errors: those of
 * chm_dev_unregister; -ENOENT not a simulated device. */
int chm_sim_unregister(const char* devname);

/* ------------------------------------------------------------------ arm */

#define CHM_SIM_ARM_MAX 6

/* A serial chain of rigid links in the vertical x-z plane: joint axes
 * parallel to y, link i's angle from +x toward +z is q1 + ... + qi, gravity
 * along -z. Link i: length, mass, centre of mass at distance com from its
 * joint, moment of inertia about its centre of mass, viscous friction at
 * its joint (N*m*s/rad), and an amplifier that saturates at +-tau_max.
 * Dynamics M(q) qdd + h(q, qd) + B qd = tau + J^T f_contact, integrated by
 * RK4 with the fixed step dt_s. */
typedef struct chm_sim_arm_config {
    uint32_t joints;      /* 1..CHM_SIM_ARM_MAX */
    uint32_t clock;       /* enum chm_sim_clock */
    uint32_t stop_mode;   /* enum chm_sim_stop_mode */
    double dt_s;          /* integration step, default 0.5 ms */
    double gravity;       /* m/s^2, default 9.81 */
    double length[CHM_SIM_ARM_MAX], mass[CHM_SIM_ARM_MAX], com[CHM_SIM_ARM_MAX];
    double inertia[CHM_SIM_ARM_MAX], friction[CHM_SIM_ARM_MAX], tau_max[CHM_SIM_ARM_MAX];
    double q0[CHM_SIM_ARM_MAX], qd0[CHM_SIM_ARM_MAX];
    int contact;          /* 1: a horizontal surface at z = surface_z pushes the tip */
    double surface_z;     /* m */
    double contact_k;     /* N/m, default 1e4 */
    double contact_c;     /* N*s/m, default 50 */
    /* A gripper at the tip: a 1-DOF jaw whose opening moves toward its
     * command (0..grip_open_max) at grip_speed; closed on the object it
     * stops at object_width and squeezes it with
     * min(grip_force_max, grip_k * (object_width - command)). */
    int gripper;
    double grip_open_max; /* m, default 0.08 (the jaws start fully open) */
    double grip_speed;    /* m/s, default 0.1 */
    double grip_force_max; /* N, default 40 */
    double grip_k;        /* N/m, default 2000 */
    /* An object to grasp (needs the gripper and the surface): a point mass
     * resting on the surface at (object_x, surface_z). Closing jaws take it
     * when it lies within grasp_reach of the tip as they pass its width; it
     * is held while the squeeze carries its weight (friction 0.5 on each
     * jaw: grip force >= mass * gravity), moving with the tip (its mass
     * added at the tip, so the arm feels it); released (jaws opened to its
     * width, or a squeeze too weak) it falls straight down onto the
     * surface. */
    int object;
    double object_x;      /* m */
    double object_mass;   /* kg, default 0.2 */
    double object_width;  /* m, default 0.04 (< grip_open_max) */
    double grasp_reach;   /* m, default 0.02 */
} chm_sim_arm_config_t;

/* Defaults: links 0.5 m, 1 kg, com 0.25 m, inertia m*l^2/12, friction 0.1,
 * tau_max 50 N*m, at rest at q = 0; monotonic clock; zero-torque stop; no
 * gripper, no object (their parameters get the defaults above). */
void chm_sim_arm_config_init(chm_sim_arm_config_t* cfg, uint32_t joints);

/* Create the arm's file (and FIFO) atomically. Errors: -EINVAL bad config;
 * -EEXIST; -errno. */
int chm_sim_arm_create(const char* path, const chm_sim_arm_config_t* cfg);

typedef struct chm_sim_arm_state {
    uint64_t t_ns;        /* simulated time since creation */
    uint64_t steps;       /* integration steps so far */
    uint32_t joints;
    uint32_t stopped;     /* safe stop latched */
    uint32_t in_contact;
    double q[CHM_SIM_ARM_MAX], qd[CHM_SIM_ARM_MAX];
    double tau_cmd[CHM_SIM_ARM_MAX]; /* commanded (after amplifier saturation) */
    double tau[CHM_SIM_ARM_MAX];     /* acting on the joints (0 in safe stop) */
    double tip[2], tip_vel[2];       /* tip position and velocity (x, z) */
    double wrench[6];     /* contact force/torque on the tip (Fx Fy Fz Tx Ty Tz), world frame */
    double kinetic, potential;       /* J; potential is 0 at z = 0 */
    /* Gripper and object (zero without them). */
    double grip_cmd;      /* commanded opening, m */
    double grip_opening;  /* m */
    double grip_force;    /* squeeze on the object, N */
    uint32_t held;        /* the object is held */
    uint32_t pad_;
    double object[2], object_vel[2]; /* the object's position (x, z) and velocity */
} chm_sim_arm_state_t;

/* Advance (monotonic clock) and copy the state. Errors: -EINVAL not an arm. */
int chm_sim_arm_read(chm_sim_t* sim, chm_sim_arm_state_t* out);
/* Integrate `steps` fixed steps now (any clock mode) and raise the line. */
int chm_sim_arm_step(chm_sim_t* sim, uint64_t steps);
/* The amplifiers' input (saturated at tau_max). Errors: -EINVAL wrong n or
 * not an arm; CHM_EACT_STOPPED-like -ESHUTDOWN in safe stop. */
int chm_sim_arm_set_torque(chm_sim_t* sim, const double* tau, uint32_t n);
/* Place the arm (tests): q and qd (NULL = zero). */
int chm_sim_arm_set_state(chm_sim_t* sim, const double* q, const double* qd, uint32_t n);
/* The gripper's commanded opening (m, clamped to [0, grip_open_max]).
 * Errors: -EINVAL not an arm with a gripper, or NaN. */
int chm_sim_arm_set_grip(chm_sim_t* sim, double opening);
/* Safe stop (latched) / leave it (torque 0). Neither moves the gripper: a
 * safe stop must not drop what it holds. */
int chm_sim_arm_stop(chm_sim_t* sim);
int chm_sim_arm_resume(chm_sim_t* sim);

/* --------------------------------------------------- force/torque sensor */

/* Mounted at the arm's tip (arm_path set: reads the arm's contact wrench)
 * or on a probe whose position and velocity another process writes
 * (arm_path empty): force along +z = max(0, k*(surface_z - z) - c*vz)
 * while z < surface_z, else 0. */
typedef struct chm_sim_ft_config {
    char arm_path[CHM_SIM_PATH_MAX];
    double surface_z, contact_k, contact_c; /* probe mode */
} chm_sim_ft_config_t;

void chm_sim_ft_config_init(chm_sim_ft_config_t* cfg);
int chm_sim_ft_create(const char* path, const chm_sim_ft_config_t* cfg);
/* Probe mode: where the probe is (x y z, m) and its velocity (m/s). */
int chm_sim_ft_set_probe(chm_sim_t* sim, const double pos[3], const double vel[3]);
/* The wrench (Fx Fy Fz in N, Tx Ty Tz in N*m) and its time. */
int chm_sim_ft_read(chm_sim_t* sim, double wrench[6], uint64_t* t_ns);

/* ------------------------------------------------------ A/D and D/A */

#define CHM_SIM_ADC_MAX 16

/* Inputs and outputs over [vmin, vmax] volts with bits_in / bits_out of
 * resolution: code = round((v - vmin) / lsb), lsb = (vmax - vmin) /
 * (2^bits - 1), clamped to [0, 2^bits - 1]. */
typedef struct chm_sim_adc_config {
    uint32_t n_in, n_out;       /* 0..CHM_SIM_ADC_MAX each */
    uint32_t bits_in, bits_out; /* 1..24 */
    double vmin, vmax;
} chm_sim_adc_config_t;

void chm_sim_adc_config_init(chm_sim_adc_config_t* cfg);
int chm_sim_adc_create(const char* path, const chm_sim_adc_config_t* cfg);
/* The analog voltage at input `ch` (converted at once; raises the line). */
int chm_sim_adc_set_input(chm_sim_t* sim, uint32_t ch, double volts);
/* The D/A output `ch`: its volts (quantised) and code. */
int chm_sim_adc_get_output(chm_sim_t* sim, uint32_t ch, double* volts, int32_t* code);
/* The A/D input `ch` as converted: volts (quantised) and code. */
int chm_sim_adc_get_input(chm_sim_t* sim, uint32_t ch, double* volts, int32_t* code);

/* ------------------------------------------------------ serial port */

/* Line settings (ioctl CHM_SERIAL_IOC_SET_LINE / GET_LINE). Applied to
 * the pty's termios, which the other end sees; a Linux pty keeps 8 data
 * bits without parity whatever is asked, so only the speed, stop bits and
 * flow control reach it. GET_LINE returns the settings as configured. */
typedef struct chm_serial_line {
    uint32_t baud;       /* one of the POSIX speeds, 50..4000000 */
    uint8_t data_bits;   /* 5..8 */
    char parity;         /* 'N', 'E', 'O' */
    uint8_t stop_bits;   /* 1, 2 */
    uint8_t rtscts;      /* hardware flow control */
} chm_serial_line_t;

#define CHM_SERIAL_IOC_PEER_NAME   0x8001 /* arg char[CHM_SIM_PATH_MAX]: the pty's other end */
#define CHM_SERIAL_IOC_SET_LINE    0x8002 /* arg const chm_serial_line_t* */
#define CHM_SERIAL_IOC_GET_LINE    0x8003 /* arg chm_serial_line_t* */
#define CHM_SERIAL_IOC_SET_TIMEOUT 0x8004 /* arg const int32_t* ms; -1 = wait forever (default) */

/* A serial port's file: the registering RTPU opens the pseudo-terminal and
 * publishes its other end here and as the symlink "<file>.pty". */
int chm_sim_serial_create(const char* path);
/* The other end's path (empty until registered). */
int chm_sim_serial_peer(chm_sim_t* sim, char* out, size_t cap);

/* Private ioctl of the simulated arm (manual stepping through level 1). */
#define CHM_SIM_IOC_STEP      0x8101 /* arg const uint64_t*: integrate that many steps */
#define CHM_SIM_IOC_ARM_STATE 0x8102 /* arg chm_sim_arm_state_t* */

#ifdef __cplusplus
}
#endif
#endif
