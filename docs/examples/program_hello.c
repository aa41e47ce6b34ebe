/* docs/examples/program_hello.c */
#include <stdio.h>

#include "chimera/chimera.h"

/* A control program: an ordinary main, run as a task by the RTPU. */
int main(int argc, char **argv) {
    printf("%s: %d argument(s), task %lld\n", argv[0], argc - 1, (long long)chm_task_self());
    /* Host files go through the host server; without one: an error. */
    int fd = chm_xfs_open("notes.txt", CHM_XFS_RDONLY, 0);
    if (fd >= 0) {
        if (chm_xfs_close(fd) != 0) return 1;
    } else {
        printf("no host files here: %s\n", chm_err_last());
    }
    for (int i = 0; i < 3; ++i)
        if (chm_task_pause_until(chm_time_now() + 1000000) != 0) return 1;
    return 7; /* the program's exit status */
}
