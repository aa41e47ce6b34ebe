/* chimera-msgq-pingpong: the msgq_wake_rt2 pattern alone, for counting
 * what it costs the host. Two host processes (RTPUs 1 and 2, no kernel)
 * pinned to one CPU pass a 24-byte message back and forth through two
 * queues in common memory, each sleeping in receive on its waiter record's
 * futex. Prints RT/2. Run it under perf to count system calls and context
 * switches per direction:
 *
 *   perf stat -e syscalls:sys_enter_futex,context-switches \
 *       build-release/bench/chimera-msgq-pingpong 20000
 *
 * (about one futex call and one switch per direction on Linux 6.18:
 * the sender's FUTEX_WAKE, where the receiver preempts it, then the
 * receiver's FUTEX_WAIT; the sender finds its reply without a call.)
 * Usage: chimera-msgq-pingpong [ROUND_TRIPS [CPU]] */
#define _GNU_SOURCE
#include <sched.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "chimera/bp.h"
#include "chimera/msgq.h"

static double now_s(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + (double)t.tv_nsec * 1e-9;
}

static int fail(const char* what) {
    fprintf(stderr, "chimera-msgq-pingpong: %s: %s\n", what, chm_bp_last_error());
    return 1;
}

int main(int argc, char** argv) {
    const int n = argc > 1 ? atoi(argv[1]) : 20000;
    const int cpu = argc > 2 ? atoi(argv[2]) : 0;
    if (n <= 0 || cpu < 0) {
        fprintf(stderr, "usage: chimera-msgq-pingpong [ROUND_TRIPS [CPU]]\n");
        return 2;
    }
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(cpu, &set);
    if (sched_setaffinity(0, sizeof set, &set) != 0) perror("sched_setaffinity (running unpinned)");

    char path[64];
    snprintf(path, sizeof path, "/dev/shm/chm-pingpong-%d.bp", (int)getpid());
    chm_bp_config_t c;
    chm_bp_config_init(&c);
    if (chm_bp_create(path, &c) != 0) return fail("create");
    int rc = 1;
    if (chm_bp_join(path, 1, "ping") != 0) {
        fail("join");
        goto out;
    }
    chm_msgq_attr_t a;
    chm_msgq_attr_init(&a);
    a.max_count = 8;
    a.max_msg = 24;
    chm_msgq_t *down, *up;
    if (chm_msgq_create("down", &a, CHM_MSGQ_COMMON, &down) || chm_msgq_create("up", &a, CHM_MSGQ_COMMON, &up)) {
        fail("queue");
        goto out;
    }
    const pid_t child = fork();
    if (child == 0) {
        chm_msgq_t *d, *u;
        char buf[24];
        if (chm_bp_join(path, 2, "pong") || chm_msgq_open("down", &d) || chm_msgq_open("up", &u)) _exit(3);
        for (int i = 0; i < n; ++i)
            if (chm_msgq_receive(d, buf, sizeof buf, NULL) != 24 || chm_msgq_send(u, 2, 0, buf, 24) != 0) _exit(4);
        _exit(0);
    }
    char buf[24];
    memset(buf, 7, sizeof buf);
    const double t0 = now_s();
    for (int i = 0; i < n; ++i)
        if (chm_msgq_send(down, 1, 0, buf, 24) != 0 || chm_msgq_receive(up, buf, sizeof buf, NULL) != 24) break;
    const double t1 = now_s();
    int st = 0;
    waitpid(child, &st, 0);
    if (WIFEXITED(st) && WEXITSTATUS(st) == 0) {
        printf("%d round trips, RT/2 %.2f us\n", n, (t1 - t0) / n / 2 * 1e6);
        rc = 0;
    } else {
        fprintf(stderr, "chimera-msgq-pingpong: the partner failed (status %d)\n", st);
    }
out:
    (void)!chm_bp_leave();
    unlink(path);
    return rc;
}
