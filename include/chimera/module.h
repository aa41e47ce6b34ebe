/* Chimera control modules (port-based objects): what a module's author
 * writes. A module is a shared object exporting one descriptor,
 *
 *     const chm_module_desc_t chm_module = { CHM_MODULE_ABI, "joint_pd", ... };
 *
 * naming its input and output state variables (chimera/svar.h), its
 * parameters and its entry points. The servo framework (chimera/servo.h)
 * loads it on any RTPU, runs its entry points in Chimera tasks there, and
 * does the copy-in of its inputs before every cycle and the copy-out of its
 * outputs after it: a module only reads and writes its local copies.
 *
 * States: not created -> init -> OFF -> on -> ON (cycle runs every period)
 * -> off -> OFF -> kill -> not created. An entry that returns non-zero,
 * raises an error signal or faults puts the module in ERROR: `error` runs
 * (if given), outputs with a safe value get it, the others hold their last
 * value; `clear` (if given) returns it to OFF. Build a module with
 *     cc -shared -fPIC -o libjoint_pd.so joint_pd.c $(pkg-config --cflags chimera)
 * (no need to link libchimera: the RTPU that loads it provides it). */
#ifndef CHIMERA_MODULE_H
#define CHIMERA_MODULE_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define CHM_MODULE_ABI 1          /* the descriptor layout this header defines */
#define CHM_MODULE_SYMBOL "chm_module"
#define CHM_MODULE_PARAMS_MAX 16
#define CHM_MODULE_VARS_MAX 16    /* inputs, and outputs, each */

typedef struct chm_module chm_module_t; /* one instance, as its entries see it */

/* A parameter: a typed configuration constant, changed between cycles by
 * chm_servo_control. The value must lie in [min, max]. */
typedef struct {
    const char* name;
    double def, min, max;
    const char* unit; /* may be NULL */
} chm_module_param_t;

/* An output's safe value: every element of the output is set to `value`
 * (converted to its type) when the module enters ERROR. */
typedef struct {
    const char* output;
    double value;
} chm_module_safe_t;

/* An entry point: 0 on success, anything else is the module's error code
 * (the module goes to ERROR). */
typedef int (*chm_module_entry_t)(chm_module_t* m);

typedef struct chm_module_desc {
    uint32_t abi;                       /* CHM_MODULE_ABI */
    const char* name;                   /* the module's (class) name */
    const char* const* inputs;          /* state variables copied in */
    size_t n_inputs;
    const char* const* outputs;         /* state variables copied out */
    size_t n_outputs;
    const chm_module_param_t* params;
    size_t n_params;
    const chm_module_safe_t* safe;      /* may be NULL */
    size_t n_safe;
    size_t state_size;                  /* bytes of private, zeroed state */
    chm_module_entry_t init, on, cycle, off, kill;  /* required */
    int (*error)(chm_module_t* m, int code);         /* optional */
    chm_module_entry_t clear;                       /* optional */
} chm_module_desc_t;

/* ---- calls for a module's entry points (any entry, in its task) ---- */

/* The local copy of state variable `name` (an input or an output of the
 * module), 16-byte aligned; look it up in init and keep the pointer.
 * NULL when the module has no such variable. */
void* chm_module_var(chm_module_t* m, const char* name);

/* The parameters' current values, in descriptor order. Valid as long as
 * the module exists; changed only between cycles. */
const double* chm_module_params(const chm_module_t* m);

/* One parameter's current value by name; NaN when there is none. */
double chm_module_param(const chm_module_t* m, const char* name);

/* The module's private state (state_size zeroed bytes; NULL if 0). */
void* chm_module_state(chm_module_t* m);

/* Its instance name (unique on its RTPU), its period in ns, the release
 * time of the cycle running now (0 outside cycle) and the number of
 * cycles run since it was created. */
const char* chm_module_name(const chm_module_t* m);
uint64_t chm_module_period_ns(const chm_module_t* m);
uint64_t chm_module_release_ns(const chm_module_t* m);
uint64_t chm_module_cycles(const chm_module_t* m);

#ifdef __cplusplus
}
#endif
#endif
