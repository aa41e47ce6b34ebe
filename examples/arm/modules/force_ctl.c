/* Module force_ctl: hybrid force/position control at the tip. Along x a
 * Cartesian PD holds the reference's x; along z the tip presses down on
 * whatever is below with f_set, measured by the F/T sensor:
 *   Fx = kx (x_ref - x) - dx vx
 *   Fz = -(f_set + kf (f_set - f_meas)) - dz vz
 *   tau = J^T F + tau_g - kd qd
 * Off contact f_meas is 0, so the tip descends at (1 + kf) f_set / dz; in
 * contact it settles where the surface pushes back with f_set. */
#include <chimera/module.h>

#include "../arm.h"

typedef struct {
    const double *q, *qd, *x_ref, *f, *tau_g;
    double* tau;
} fc_t;

static const char* const inputs[] = {SV_Q, SV_QD, SV_X_REF, SV_F, SV_TAU_G};
static const char* const outputs[] = {SV_TAU};
static const chm_module_param_t params[] = {
    {"f_set", 5, 0, 50, "N"},
    {"kx", 1000, 0, 10000, "N/m"},
    {"dx", 60, 0, 1000, "N*s/m"},
    {"kf", 0.5, 0, 5, NULL},
    {"dz", 50, 1, 1000, "N*s/m"},
    {"kd", 1.0, 0, 50, "N*m*s/rad"},
};
static const chm_module_safe_t safe[] = {{SV_TAU, 0.0}};

static int init(chm_module_t* m) {
    fc_t* s = chm_module_state(m);
    s->q = chm_module_var(m, SV_Q);
    s->qd = chm_module_var(m, SV_QD);
    s->x_ref = chm_module_var(m, SV_X_REF);
    s->f = chm_module_var(m, SV_F);
    s->tau_g = chm_module_var(m, SV_TAU_G);
    s->tau = chm_module_var(m, SV_TAU);
    return 0;
}
static int on(chm_module_t* m) { (void)m; return 0; }
static int off(chm_module_t* m) { (void)m; return 0; }
static int kill_(chm_module_t* m) { (void)m; return 0; }

static int cycle(chm_module_t* m) {
    fc_t* s = chm_module_state(m);
    const double* p = chm_module_params(m);
    double x[2], j[4];
    arm_fk(s->q, x);
    arm_jacobian(s->q, j);
    const double vx = j[0] * s->qd[0] + j[1] * s->qd[1], vz = j[2] * s->qd[0] + j[3] * s->qd[1];
    const double fx = p[1] * (s->x_ref[0] - x[0]) - p[2] * vx;
    const double fz = -(p[0] + p[3] * (p[0] - s->f[1])) - p[4] * vz;
    s->tau[0] = j[0] * fx + j[2] * fz + s->tau_g[0] - p[5] * s->qd[0];
    s->tau[1] = j[1] * fx + j[3] * fz + s->tau_g[1] - p[5] * s->qd[1];
    return 0;
}

const chm_module_desc_t chm_module = {
    .abi = CHM_MODULE_ABI, .name = "force_ctl",
    .inputs = inputs, .n_inputs = 5, .outputs = outputs, .n_outputs = 1,
    .params = params, .n_params = 6, .safe = safe, .n_safe = 1,
    .state_size = sizeof(fc_t),
    .init = init, .on = on, .cycle = cycle, .off = off, .kill = kill_,
};
