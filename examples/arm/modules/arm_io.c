/* Module arm_io: the arm's sensors and actuators. Its init creates the
 * simulated arm (gripper, surface, object) and the force/torque sensor at
 * its tip in the simulation directory (chm_sim_dir(): $CHIMERA_SIM_DIR),
 * registers them as devices of this RTPU and opens them through level 2
 * (chimera/sensor.h); kill closes, unregisters and removes them.
 *
 * Each cycle: copy-in brings the torque and grip commands; the cycle reads
 * the arm (q, qd, jaws), the F/T sensor and the object's state, and
 * commands torques and grip; copy-out publishes the readings. The arm runs
 * on this RTPU's clock (CHM_SIM_CLOCK_KERNEL): it advances only when read
 * here. It starts braked (hold-mode safe stop) and the brakes come off
 * after `brake_cycles` cycles, once the controllers' first commands are in
 * the table; an error brakes it again. */
#include <chimera/module.h>
#include <chimera/sensor.h>
#include <stdio.h>
#include <string.h>

#include "../arm.h"
#include "sim.h"

#define ARM_DEV "armdemo_arm"
#define FT_DEV "armdemo_ft"

typedef struct {
    double *q, *qd, *f, *grip, *obj, *t;
    const double *tau, *grip_cmd;
    int sd, ad, fd;          /* arm sensor, arm actuator, F/T sensor */
    int registered;          /* 1: arm, 2: both */
    unsigned long long on_cycles;
    char arm_path[CHM_SIM_PATH_MAX], ft_path[CHM_SIM_PATH_MAX];
} io_t;

static const char* const inputs[] = {SV_TAU, SV_GRIP_CMD};
static const char* const outputs[] = {SV_Q, SV_QD, SV_F, SV_GRIP, SV_OBJ, SV_T};
static const chm_module_param_t params[] = {
    {"object_x", ARM_OBJECT_X, 0.2, 0.95, "m"},
    {"home_x", ARM_HOME_X, 0.1, 0.95, "m"},
    {"home_z", ARM_HOME_Z, -0.5, 0.5, "m"},
    {"brake_cycles", 10, 1, 1000, NULL},
};

static void close_all(io_t* s) {
    if (s->ad >= 0) (void)!chm_dev_close(s->ad); /* a safe stop: brakes on */
    if (s->sd >= 0) (void)!chm_dev_close(s->sd);
    if (s->fd >= 0) (void)!chm_dev_close(s->fd);
    s->ad = s->sd = s->fd = -1;
    if (s->registered > 1) chm_sim_unregister(FT_DEV);
    if (s->registered > 0) chm_sim_unregister(ARM_DEV);
    s->registered = 0;
    chm_sim_remove(s->ft_path);
    chm_sim_remove(s->arm_path);
}

static int fail(io_t* s, const char* what, int r) {
    fprintf(stderr, "arm_io: %s: %s\n", what, r < 0 ? strerror(-r) : "failed");
    close_all(s);
    return 1;
}

static int init(chm_module_t* m) {
    io_t* s = chm_module_state(m);
    s->sd = s->ad = s->fd = -1;
    s->q = chm_module_var(m, SV_Q);
    s->qd = chm_module_var(m, SV_QD);
    s->f = chm_module_var(m, SV_F);
    s->grip = chm_module_var(m, SV_GRIP);
    s->obj = chm_module_var(m, SV_OBJ);
    s->t = chm_module_var(m, SV_T);
    s->tau = chm_module_var(m, SV_TAU);
    s->grip_cmd = chm_module_var(m, SV_GRIP_CMD);
    if (chm_sim_path(ARM_DEV, s->arm_path, sizeof s->arm_path) < 0 ||
        chm_sim_path(FT_DEV, s->ft_path, sizeof s->ft_path) < 0)
        return 1;
    chm_sim_remove(s->ft_path); /* left by a run that was killed */
    chm_sim_remove(s->arm_path);

    chm_sim_arm_config_t c;
    chm_sim_arm_config_init(&c, 2);
    c.clock = CHM_SIM_CLOCK_KERNEL;
    c.stop_mode = CHM_SIM_STOP_HOLD;
    c.contact = 1;
    c.surface_z = ARM_SURFACE_Z;
    c.gripper = 1;
    c.object = 1;
    c.object_x = chm_module_param(m, "object_x");
    c.object_mass = ARM_OBJECT_MASS;
    const double home[2] = {chm_module_param(m, "home_x"), chm_module_param(m, "home_z")};
    if (arm_ik(home, c.q0) != 0) return fail(s, "home out of reach", 0);
    int r = chm_sim_arm_create(s->arm_path, &c);
    if (r < 0) return fail(s, s->arm_path, r);
    chm_sim_ft_config_t fc;
    chm_sim_ft_config_init(&fc);
    snprintf(fc.arm_path, sizeof fc.arm_path, "%s", s->arm_path);
    if ((r = chm_sim_ft_create(s->ft_path, &fc)) < 0) return fail(s, s->ft_path, r);
    if ((r = chm_sim_register(ARM_DEV, s->arm_path)) < 0) return fail(s, "register arm", r);
    s->registered = 1;
    if ((r = chm_sim_register(FT_DEV, s->ft_path)) < 0) return fail(s, "register F/T", r);
    s->registered = 2;
    if ((s->sd = chm_sensor_open(ARM_DEV)) < 0) return fail(s, "open arm sensor", s->sd);
    if ((s->fd = chm_sensor_open(FT_DEV)) < 0) return fail(s, "open F/T sensor", s->fd);
    if ((s->ad = chm_actuator_open(ARM_DEV, NULL)) < 0) return fail(s, "open arm actuator", s->ad);
    if ((r = chm_actuator_stop(s->ad)) < 0) return fail(s, "brake", r);
    return 0;
}

static int on(chm_module_t* m) {
    ((io_t*)chm_module_state(m))->on_cycles = 0;
    return 0;
}

static int cycle(chm_module_t* m) {
    io_t* s = chm_module_state(m);
    chm_sensor_sample_t a, f;
    if (chm_sensor_read(s->sd, &a) < 0 || a.n != 6 || chm_sensor_read(s->fd, &f) < 0) return 2;
    double obj[3]; /* registers after the arm's and the grip command: held, x, z */
    if (chm_dev_pread(s->sd, obj, sizeof obj, (4 * 2 + 4 + 3) * sizeof(double)) != (int64_t)sizeof obj) return 3;
    for (int i = 0; i < 2; ++i) {
        s->q[i] = a.v[i];
        s->qd[i] = a.v[2 + i];
    }
    s->grip[0] = a.v[4];
    s->grip[1] = a.v[5];
    s->f[0] = f.v[0];
    s->f[1] = f.v[2];
    s->obj[0] = obj[1];
    s->obj[1] = obj[2];
    s->obj[2] = obj[0];
    *s->t = (double)a.t_ns * 1e-9;
    if (++s->on_cycles < (unsigned long long)chm_module_param(m, "brake_cycles")) return 0;
    if (s->on_cycles == (unsigned long long)chm_module_param(m, "brake_cycles") && chm_actuator_resume(s->ad) < 0)
        return 4;
    const double cmd[3] = {s->tau[0], s->tau[1], *s->grip_cmd};
    const int r = chm_actuator_write(s->ad, cmd, 3);
    return r == 0 || r == CHM_ACT_CLAMPED ? 0 : 5;
}

static int off(chm_module_t* m) {
    return chm_actuator_stop(((io_t*)chm_module_state(m))->ad) < 0;
}

static int kill_(chm_module_t* m) {
    close_all(chm_module_state(m));
    return 0;
}

static int error(chm_module_t* m, int code) {
    (void)code;
    io_t* s = chm_module_state(m);
    if (s->ad >= 0) (void)!chm_actuator_stop(s->ad);
    return 0;
}

const chm_module_desc_t chm_module = {
    .abi = CHM_MODULE_ABI, .name = "arm_io",
    .inputs = inputs, .n_inputs = 2, .outputs = outputs, .n_outputs = 6,
    .params = params, .n_params = 4,
    .state_size = sizeof(io_t),
    .init = init, .on = on, .cycle = cycle, .off = off, .kill = kill_, .error = error,
};
