/* The Chimera II paper's error-handling example: with global error handling
 * on, a UNIX call needs no check of its return value. The failing open
 * raises an error signal; the default handler prints one precise line and
 * aborts only the task that failed, while the RTPU's other tasks run on. */
#include <fcntl.h>
#include <stdio.h>

/* Global error handling makes checks unneeded: no unchecked-status
 * warnings (chimera/status.h). */
#define CHM_ALLOW_UNCHECKED
#include "chimera/chimera.h"

static void reader(void *arg) {
    (void)arg;
    chm_err_global(1);                                 /* calls raise error signals */
    int fd = chm_unix_open("no-such-file", O_RDONLY);  /* no check needed */
    printf("never printed: fd %d\n", fd);
}

static void survivor(void *arg) {
    (void)arg;
    chm_task_pause_until(chm_time_now() + 10000000);  /* after the reader failed */
    printf("the RTPU runs on\n");
}

int main(void) {
    chm_kernel_init(NULL);
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = "reader";
    a.priority = 2;
    chm_task_spawn(NULL, reader, NULL, &a);
    a.name = "survivor";
    a.priority = 1;
    chm_task_spawn(NULL, survivor, NULL, &a);
    return chm_kernel_run();
}
