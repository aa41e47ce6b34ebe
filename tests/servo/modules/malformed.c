/* A test module whose descriptor is wrong as MALFORMED says: 1 another
 * ABI, 2 no cycle entry, 3 an input that is not declared. */
#include <chimera/module.h>

#if MALFORMED == 3
static const char* const inputs[] = {"not_declared"};
#endif
static int ok(chm_module_t* m) { (void)m; return 0; }

const chm_module_desc_t chm_module = {
#if MALFORMED == 1
    .abi = 99,
#else
    .abi = CHM_MODULE_ABI,
#endif
    .name = "malformed",
#if MALFORMED == 3
    .inputs = inputs, .n_inputs = 1,
#endif
    .init = ok, .on = ok,
#if MALFORMED != 2
    .cycle = ok,
#endif
    .off = ok, .kill = ok,
};
