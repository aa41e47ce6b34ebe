/* docs/examples/program_load.c */
#include <stdio.h>

#include "chimera/chimera.h"

int main(void) {
    chm_kernel_config_t cfg;
    chm_kernel_config_init(&cfg);
    cfg.virtual_clock = 1;
    if (chm_kernel_init(&cfg) != 0) {
        printf("chm_kernel_init: %s\n", chm_err_last());
        return 1;
    }
    const char *argv[] = {"hello", "world"};
    chm_tid_t main_task;
    int prog = chm_program_load("./program_hello.so", 2, argv, NULL, &main_task);
    if (prog < 0) {
        printf("chm_program_load: %s\n", chm_err_last());
        chm_kernel_fini();
        return 1;
    }
    int r = chm_kernel_run(); /* until the program's main returns */
    int status = -1;
    if (r == 0) r = chm_program_status(prog, &status);
    chm_kernel_fini();
    if (r != 0) {
        printf("chm_program_status: %d\n", r);
        return 1;
    }
    printf("main returned %d\n", status);
    return status != 7;
}
