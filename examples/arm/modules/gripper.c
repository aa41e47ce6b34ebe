/* Module gripper: the gripper controller. With close = 0 it opens the jaws
 * to `open`; with close = 1 it closes them at `rate` until they touch, then
 * servoes the squeeze to f_grip by integral action on the jaw command
 * (the jaws squeeze in proportion to how far the command lies inside what
 * they hold). Off, it leaves the last command in place: what is held stays
 * held. */
#include <chimera/module.h>

#include "../arm.h"

typedef struct {
    const double* grip;
    double* cmd;
    int started;
} gr_t;

static const char* const inputs[] = {SV_GRIP};
static const char* const outputs[] = {SV_GRIP_CMD};
static const chm_module_param_t params[] = {
    {"close", 0, 0, 1, NULL},
    {"f_grip", 10, 0, 40, "N"},
    {"open", 0.08, 0, 0.08, "m"},
    {"rate", 0.1, 0.001, 1, "m/s"},
    {"ki", 0.004, 0, 0.1, "m/(N*s)"},
};

static int init(chm_module_t* m) {
    gr_t* s = chm_module_state(m);
    s->grip = chm_module_var(m, SV_GRIP);
    s->cmd = chm_module_var(m, SV_GRIP_CMD);
    return 0;
}
static int on(chm_module_t* m) { (void)m; return 0; }
static int off(chm_module_t* m) { (void)m; return 0; }
static int kill_(chm_module_t* m) { (void)m; return 0; }

static int cycle(chm_module_t* m) {
    gr_t* s = chm_module_state(m);
    const double* p = chm_module_params(m);
    const double dt = (double)chm_module_period_ns(m) * 1e-9;
    if (!s->started) { /* continue from the jaws' measured opening */
        *s->cmd = s->grip[0];
        s->started = 1;
    }
    if (p[0] == 0) {
        *s->cmd = p[2];
        return 0;
    }
    if (s->grip[1] <= 0) { /* touching nothing yet */
        *s->cmd -= p[3] * dt;
        if (*s->cmd < 0) *s->cmd = 0;
    } else {
        *s->cmd += p[4] * (s->grip[1] - p[1]) * dt;
    }
    return 0;
}

const chm_module_desc_t chm_module = {
    .abi = CHM_MODULE_ABI, .name = "gripper",
    .inputs = inputs, .n_inputs = 1, .outputs = outputs, .n_outputs = 1,
    .params = params, .n_params = 5,
    .state_size = sizeof(gr_t),
    .init = init, .on = on, .cycle = cycle, .off = off, .kill = kill_,
};
