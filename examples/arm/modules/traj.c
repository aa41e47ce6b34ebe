/* Module traj: the trajectory generator. Moves the joint reference from
 * where it is to the joint angles that put the tip at (x, z), in `dur`
 * seconds along a quintic (zero velocity and acceleration at both ends).
 * A new segment starts when the controller changes `seq` (set x, z, dur
 * and from_q first): from the current reference, or from the measured
 * joint angles when from_q is 1 (after force control moved the arm off the
 * reference). Until the arm's first sample the reference is that sample. */
#include <chimera/module.h>

#include "../arm.h"

typedef struct {
    const double *q, *t;
    double *q_ref, *qd_ref, *x_ref;
    double from[2], to[2];
    uint64_t t0_ns, dur_ns;
    double seq;
    int started;
} traj_t;

static const char* const inputs[] = {SV_Q, SV_T};
static const char* const outputs[] = {SV_Q_REF, SV_QD_REF, SV_X_REF};
static const chm_module_param_t params[] = {
    {"x", ARM_HOME_X, -1, 1, "m"},
    {"z", ARM_HOME_Z, -1, 1, "m"},
    {"dur", 1.0, 0.05, 60, "s"},
    {"from_q", 0, 0, 1, NULL},
    {"seq", 0, 0, 1e9, NULL},
};

static int init(chm_module_t* m) {
    traj_t* s = chm_module_state(m);
    s->q = chm_module_var(m, SV_Q);
    s->t = chm_module_var(m, SV_T);
    s->q_ref = chm_module_var(m, SV_Q_REF);
    s->qd_ref = chm_module_var(m, SV_QD_REF);
    s->x_ref = chm_module_var(m, SV_X_REF);
    return 0;
}
static int on(chm_module_t* m) { (void)m; return 0; }
static int off(chm_module_t* m) { (void)m; return 0; }
static int kill_(chm_module_t* m) { (void)m; return 0; }

static int cycle(chm_module_t* m) {
    traj_t* s = chm_module_state(m);
    const uint64_t now = chm_module_release_ns(m);
    if (!s->started) {
        if (*s->t <= 0) return 0; /* no sample of the arm yet */
        for (int i = 0; i < 2; ++i) s->from[i] = s->to[i] = s->q[i];
        s->seq = chm_module_param(m, "seq");
        s->t0_ns = now;
        s->dur_ns = 1;
        s->started = 1;
    }
    const double seq = chm_module_param(m, "seq");
    if (seq != s->seq) {
        const double x[2] = {chm_module_param(m, "x"), chm_module_param(m, "z")};
        double goal[2];
        if (arm_ik(x, goal) != 0) return 1; /* out of reach: ERROR, the reference holds */
        for (int i = 0; i < 2; ++i) s->from[i] = chm_module_param(m, "from_q") != 0 ? s->q[i] : s->q_ref[i];
        s->to[0] = goal[0];
        s->to[1] = goal[1];
        s->t0_ns = now;
        s->dur_ns = (uint64_t)(chm_module_param(m, "dur") * 1e9);
        s->seq = seq;
    }
    double tau = now >= s->t0_ns ? (double)(now - s->t0_ns) / (double)s->dur_ns : 0.0;
    if (tau > 1.0) tau = 1.0;
    const double p = tau * tau * tau * (10 - 15 * tau + 6 * tau * tau);
    const double v = 30 * tau * tau * (1 - tau) * (1 - tau) / ((double)s->dur_ns * 1e-9);
    for (int i = 0; i < 2; ++i) {
        s->q_ref[i] = s->from[i] + (s->to[i] - s->from[i]) * p;
        s->qd_ref[i] = (s->to[i] - s->from[i]) * v;
    }
    arm_fk(s->q_ref, s->x_ref);
    return 0;
}

const chm_module_desc_t chm_module = {
    .abi = CHM_MODULE_ABI, .name = "traj",
    .inputs = inputs, .n_inputs = 2, .outputs = outputs, .n_outputs = 3,
    .params = params, .n_params = 5,
    .state_size = sizeof(traj_t),
    .init = init, .on = on, .cycle = cycle, .off = off, .kill = kill_,
};
