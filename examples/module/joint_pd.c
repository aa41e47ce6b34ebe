/* joint_pd: a control module (a port-based object). The framework copies
 * q, qd and q_ref in before every cycle and tau out after it; the module
 * only reads and writes its local copies. Shown in the README. */
#include <chimera/module.h>

typedef struct {
    const double *q, *qd, *q_ref;
    double* tau;
} pd_t;

static const char* const in[] = {"q", "qd", "q_ref"};
static const char* const out[] = {"tau"};
static const chm_module_param_t params[] = {
    {"kp", 200, 0, 2000, "N*m/rad"},
    {"kd", 15, 0, 200, "N*m*s/rad"},
};
static const chm_module_safe_t safe[] = {{"tau", 0.0}}; /* in ERROR: no torque */

static int init(chm_module_t* m) {
    pd_t* s = chm_module_state(m);
    s->q = chm_module_var(m, "q");
    s->qd = chm_module_var(m, "qd");
    s->q_ref = chm_module_var(m, "q_ref");
    s->tau = chm_module_var(m, "tau");
    return 0;
}

static int cycle(chm_module_t* m) {
    pd_t* s = chm_module_state(m);
    const double* k = chm_module_params(m); /* kp, kd: chm_servo_control changes them live */
    for (int i = 0; i < 2; ++i) s->tau[i] = k[0] * (s->q_ref[i] - s->q[i]) - k[1] * s->qd[i];
    return 0; /* non-zero: the module goes to ERROR, the rest runs on */
}

static int nothing(chm_module_t* m) {
    (void)m;
    return 0;
}

const chm_module_desc_t chm_module = {
    .abi = CHM_MODULE_ABI, .name = "joint_pd",
    .inputs = in, .n_inputs = 3, .outputs = out, .n_outputs = 1,
    .params = params, .n_params = 2, .safe = safe, .n_safe = 1,
    .state_size = sizeof(pd_t),
    .init = init, .on = nothing, .cycle = cycle, .off = nothing, .kill = nothing,
};
