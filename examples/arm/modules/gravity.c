/* Module gravity: gravity compensation. The torques that hold the arm up
 * at its measured joint angles, with the object's mass added when the jaws
 * squeeze something (a squeeze of at least `hold_force`). */
#include <chimera/module.h>

#include "../arm.h"

typedef struct {
    const double *q, *grip;
    double* tau_g;
} grav_t;

static const char* const inputs[] = {SV_Q, SV_GRIP};
static const char* const outputs[] = {SV_TAU_G};
static const chm_module_param_t params[] = {
    {"payload", ARM_OBJECT_MASS, 0, 5, "kg"},
    {"hold_force", 1.0, 0, 100, "N"},
};

static int init(chm_module_t* m) {
    grav_t* s = chm_module_state(m);
    s->q = chm_module_var(m, SV_Q);
    s->grip = chm_module_var(m, SV_GRIP);
    s->tau_g = chm_module_var(m, SV_TAU_G);
    return 0;
}
static int on(chm_module_t* m) { (void)m; return 0; }
static int off(chm_module_t* m) { (void)m; return 0; }
static int kill_(chm_module_t* m) { (void)m; return 0; }

static int cycle(chm_module_t* m) {
    grav_t* s = chm_module_state(m);
    const double* p = chm_module_params(m);
    arm_gravity(s->q, s->grip[1] >= p[1] ? p[0] : 0.0, s->tau_g);
    return 0;
}

const chm_module_desc_t chm_module = {
    .abi = CHM_MODULE_ABI, .name = "gravity",
    .inputs = inputs, .n_inputs = 2, .outputs = outputs, .n_outputs = 1,
    .params = params, .n_params = 2,
    .state_size = sizeof(grav_t),
    .init = init, .on = on, .cycle = cycle, .off = off, .kill = kill_,
};
