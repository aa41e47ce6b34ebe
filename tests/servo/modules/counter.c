/* A test module: writes state variable "v" (COUNTER_OUTPUT when built as
 * a variant) = k * 1000 + id every cycle,
 * where k is the cycle's index on the shared grid (release / period), and
 * appends k to the log segment "log.<instance>" the test created, so the
 * test can tell which module ran which cycle. */
#include <chimera/module.h>
#include <chimera/shm.h>
#include <stdint.h>
#include <stdio.h>

#define LOG_MAX 16384
typedef struct {
    uint32_t count;
    uint32_t pad;
    uint64_t k[LOG_MAX];
} cycle_log_t;

typedef struct {
    double* v;
    cycle_log_t* log;
    int on_calls, off_calls;
} state_t;

#ifndef COUNTER_OUTPUT
#define COUNTER_OUTPUT "v"
#endif
static const char* const outputs[] = {COUNTER_OUTPUT};
static const chm_module_param_t params[] = {{"id", 1, 1, 100, NULL}};

static int init(chm_module_t* m) {
    state_t* s = chm_module_state(m);
    s->v = chm_module_var(m, COUNTER_OUTPUT);
    char name[48];
    snprintf(name, sizeof name, "log.%s", chm_module_name(m));
    void* p = NULL;
    if (chm_shm_attach(name, &p, NULL) == 0) s->log = p;
    return s->v ? 0 : 1;
}
static int on(chm_module_t* m) { ((state_t*)chm_module_state(m))->on_calls++; return 0; }
static int off(chm_module_t* m) { ((state_t*)chm_module_state(m))->off_calls++; return 0; }
static int kill_(chm_module_t* m) { (void)m; return 0; }
static int cycle(chm_module_t* m) {
    state_t* s = chm_module_state(m);
    const uint64_t k = chm_module_release_ns(m) / chm_module_period_ns(m);
    *s->v = (double)k * 1000.0 + chm_module_params(m)[0];
    if (s->log && s->log->count < LOG_MAX) {
        /* The entry first, then the count that publishes it: the test
         * reads the log while this module runs. */
        s->log->k[s->log->count] = k;
        __atomic_store_n(&s->log->count, s->log->count + 1, __ATOMIC_RELEASE);
    }
    return 0;
}

const chm_module_desc_t chm_module = {
    .abi = CHM_MODULE_ABI, .name = "counter",
    .outputs = outputs, .n_outputs = 1,
    .params = params, .n_params = 1,
    .state_size = sizeof(state_t),
    .init = init, .on = on, .cycle = cycle, .off = off, .kill = kill_,
};
