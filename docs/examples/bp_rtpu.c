/* docs/examples/bp_rtpu.c */
#define _POSIX_C_SOURCE 200809L /* mkdtemp, kill */
#include <errno.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "chimera/chimera.h"

#define MS 1000000ull

static int fail(const char *what, int r) {
    printf("%s: %d %s\n", what, r, chm_err_last());
    return 1;
}

/* Start chimera-rtpu as RTPU 1 and wait (bounded) until it answers. */
static pid_t start_rtpu(const char *exe, const char *bp) {
    pid_t pid = fork();
    if (pid == 0) {
        execl(exe, exe, "--backplane", bp, "--rtpu", "1", (char *)NULL);
        _exit(127);
    }
    for (int i = 0; pid > 0 && i < 500; ++i) {
        if (chm_rtpu_ping(1, NULL) == 0) return pid;
        nanosleep(&(struct timespec){0, 10 * 1000000}, NULL);
    }
    if (pid > 0 && kill(pid, SIGKILL) == 0) waitpid(pid, NULL, 0);
    return -1;
}

static int control(const char *exe, const char *bp) {
    chm_rtpu_timeout_set(200 * MS); /* every express-mail call is bounded */
    int r = chm_rtpu_ping(1, NULL); /* nobody there yet: an error, no hang */
    if (r != -EHOSTDOWN) return fail("chm_rtpu_ping", r);
    printf("no RTPU 1 yet: %s\n", chm_err_last());
    if (!exe) {
        printf("CHIMERA_RTPU is not set: no RTPU to start\n");
        return 0;
    }
    pid_t pid = start_rtpu(exe, bp);
    if (pid < 0) return fail("start chimera-rtpu", -1);
    chm_rtpu_info_t info;
    chm_rtpu_task_t tasks[8];
    int total = 0, n = chm_rtpu_ping(1, &info);
    if (n == 0) n = chm_rtpu_tasks(1, tasks, 8, &total);
    for (int i = 0; i < n; ++i) printf("RTPU 1 runs task %s\n", tasks[i].name);
    r = chm_rtpu_stop(1, 0); /* graceful: its shutdown hooks run */
    int status = -1;
    if (waitpid(pid, &status, 0) != pid) return fail("waitpid", -errno);
    if (n < 0 || r != 0) return fail("express mail", n < 0 ? n : r);
    printf("RTPU 1 (pid %d, policy %d) stopped with status %d\n", (int)info.pid,
           (int)info.policy, WIFEXITED(status) ? WEXITSTATUS(status) : -1);
    return 0;
}

int main(void) {
    char dir[] = "/dev/shm/chm-guide-XXXXXX", path[64];
    if (!mkdtemp(dir)) return fail("mkdtemp", -errno);
    snprintf(path, sizeof path, "%s/guide.bp", dir);
    chm_bp_config_t cfg;
    chm_bp_config_init(&cfg);
    cfg.rtpu_slots = 4;
    cfg.ring_records = 8;
    cfg.local_window_size = 64 * 1024;
    cfg.common_size = 256 * 1024;
    cfg.registry_capacity = 16;
    int failed = 1;
    int r = chm_bp_create(path, &cfg);
    if (r == 0 && (r = chm_bp_attach_host(path, "guide", NULL)) == 0) {
        failed = control(getenv("CHIMERA_RTPU"), path);
        if ((r = chm_bp_leave()) != 0) failed = fail("chm_bp_leave", r);
    } else {
        fail("backplane", r);
    }
    if (unlink(path) != 0 || rmdir(dir) != 0) failed = fail("clean up", -errno);
    return failed;
}
