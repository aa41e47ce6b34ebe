/* The chaos soak's control module (modlog.h): built twice, writing
 * soak.hand (roles A and B, handed over between RTPUs) or soak.solo (role
 * S, switched alone). Each cycle sets every element of its output to
 * k * 4 + role (a torn value shows as unequal elements) and marks cycle k
 * in its role's bitmap in soak.mlog. Public API only. */
#include <chimera/module.h>
#include <chimera/shm.h>
#include <stdint.h>

#include "modlog.h"

#ifndef SOAK_MOD_OUTPUT
#define SOAK_MOD_OUTPUT "soak.hand"
#endif

typedef struct {
    double* out;
    soak_modlog_t* log;
    unsigned role;
} state_t;

static const char* const outputs[] = {SOAK_MOD_OUTPUT};
static const chm_module_param_t params[] = {{"role", 0, 0, SOAK_MOD_ROLES - 1, NULL}};

static int init(chm_module_t* m) {
    state_t* s = chm_module_state(m);
    s->out = chm_module_var(m, SOAK_MOD_OUTPUT);
    s->role = (unsigned)chm_module_params(m)[0];
    void* p = 0;
    if (chm_shm_attach("soak.mlog", &p, 0) != 0) return 2;
    s->log = p;
    return s->out ? 0 : 1;
}

static int cycle(chm_module_t* m) {
    state_t* s = chm_module_state(m);
    const uint64_t k = chm_module_release_ns(m) / chm_module_period_ns(m);
    for (int i = 0; i < SOAK_HAND_ELEMS; ++i) s->out[i] = (double)(k * 4 + s->role);
    const uint64_t i = k - s->log->base_k;
    if (k >= s->log->base_k && i < SOAK_MOD_CAP_BITS)
        __atomic_fetch_or(&s->log->bits[s->role][i >> 3], (uint8_t)(1u << (i & 7)), __ATOMIC_SEQ_CST);
    else
        __atomic_fetch_add(&s->log->beyond[s->role], 1, __ATOMIC_SEQ_CST);
    __atomic_fetch_add(&s->log->cycles[s->role], 1, __ATOMIC_SEQ_CST);
    return 0;
}

static int nothing(chm_module_t* m) {
    (void)m;
    return 0;
}

const chm_module_desc_t chm_module = {
    .abi = CHM_MODULE_ABI, .name = "soak_module",
    .outputs = outputs, .n_outputs = 1,
    .params = params, .n_params = 1,
    .state_size = sizeof(state_t),
    .init = init, .on = nothing, .cycle = cycle, .off = nothing, .kill = nothing,
};
