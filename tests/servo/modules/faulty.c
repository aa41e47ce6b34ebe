/* A test module that fails where its parameter "where" says:
 * 0 nowhere, 1 init returns 3, 2 init dereferences NULL, 3 cycle
 * dereferences NULL at its cycle "at", 4 cycle returns 7 at cycle "at",
 * 5 on returns 9. Output "f" (safe value -1) counts its cycles. */
#include <chimera/module.h>
#include <stdint.h>

static const char* const outputs[] = {"f"};
static const chm_module_param_t params[] = {{"where", 0, 0, 5, NULL}, {"at", 3, 0, 1000, NULL}};
static const chm_module_safe_t safe[] = {{"f", -1.0}};
static volatile int* volatile nowhere;
typedef struct { double* f; uint64_t n; int cleared; } state_t;

static int where(chm_module_t* m) { return (int)chm_module_params(m)[0]; }
/* The faults are the point: not the sanitizers' business (make test-asan). */
#define FAULTS_ON_PURPOSE __attribute__((no_sanitize("undefined")))
FAULTS_ON_PURPOSE static int init(chm_module_t* m) {
    state_t* s = chm_module_state(m);
    s->f = chm_module_var(m, "f");
    if (where(m) == 1) return 3;
    if (where(m) == 2) return *nowhere;
    return 0;
}
static int on(chm_module_t* m) { return where(m) == 5 ? 9 : 0; }
static int off(chm_module_t* m) { (void)m; return 0; }
static int kill_(chm_module_t* m) { (void)m; return 0; }
static int clear(chm_module_t* m) { ((state_t*)chm_module_state(m))->cleared++; return 0; }
FAULTS_ON_PURPOSE static int cycle(chm_module_t* m) {
    state_t* s = chm_module_state(m);
    ++s->n;
    *s->f = (double)s->n;
    if (s->n == (uint64_t)chm_module_params(m)[1]) {
        if (where(m) == 3) *nowhere = 1;
        if (where(m) == 4) return 7;
    }
    return 0;
}

const chm_module_desc_t chm_module = {
    .abi = CHM_MODULE_ABI, .name = "faulty",
    .outputs = outputs, .n_outputs = 1,
    .params = params, .n_params = 2,
    .safe = safe, .n_safe = 1,
    .state_size = sizeof(state_t),
    .init = init, .on = on, .cycle = cycle, .off = off, .kill = kill_, .clear = clear,
};
