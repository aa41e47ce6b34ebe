/* Module joint_pd: free-motion control. Joint PD on the reference plus
 * gravity compensation: tau = kp (q_ref - q) + kd (qd_ref - qd) + tau_g.
 * Until the arm's first sample it commands gravity compensation only. On
 * error the torques go to 0 (the safe value) and arm_io's brakes hold. */
#include <chimera/module.h>

#include "../arm.h"

typedef struct {
    const double *q, *qd, *q_ref, *qd_ref, *tau_g, *t;
    double* tau;
} pd_t;

static const char* const inputs[] = {SV_Q, SV_QD, SV_Q_REF, SV_QD_REF, SV_TAU_G, SV_T};
static const char* const outputs[] = {SV_TAU};
static const chm_module_param_t params[] = {
    {"kp", 200, 0, 2000, "N*m/rad"},
    {"kd", 15, 0, 200, "N*m*s/rad"},
};
static const chm_module_safe_t safe[] = {{SV_TAU, 0.0}};

static int init(chm_module_t* m) {
    pd_t* s = chm_module_state(m);
    s->q = chm_module_var(m, SV_Q);
    s->qd = chm_module_var(m, SV_QD);
    s->q_ref = chm_module_var(m, SV_Q_REF);
    s->qd_ref = chm_module_var(m, SV_QD_REF);
    s->tau_g = chm_module_var(m, SV_TAU_G);
    s->t = chm_module_var(m, SV_T);
    s->tau = chm_module_var(m, SV_TAU);
    return 0;
}
static int on(chm_module_t* m) { (void)m; return 0; }
static int off(chm_module_t* m) { (void)m; return 0; }
static int kill_(chm_module_t* m) { (void)m; return 0; }

static int cycle(chm_module_t* m) {
    pd_t* s = chm_module_state(m);
    const double kp = chm_module_params(m)[0], kd = chm_module_params(m)[1];
    const int ready = *s->t > 0;
    for (int i = 0; i < 2; ++i)
        s->tau[i] = s->tau_g[i] + (ready ? kp * (s->q_ref[i] - s->q[i]) + kd * (s->qd_ref[i] - s->qd[i]) : 0.0);
    return 0;
}

const chm_module_desc_t chm_module = {
    .abi = CHM_MODULE_ABI, .name = "joint_pd",
    .inputs = inputs, .n_inputs = 6, .outputs = outputs, .n_outputs = 1,
    .params = params, .n_params = 2, .safe = safe, .n_safe = 1,
    .state_size = sizeof(pd_t),
    .init = init, .on = on, .cycle = cycle, .off = off, .kill = kill_,
};
