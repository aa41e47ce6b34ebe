/* docs/examples/sched_deadline.c */
#include <stdio.h>

#include "chimera/chimera.h"

#define MS 1000000ull

static int cycle; /* static: an aborted cycle restarts the entry function */
static int handled;

static enum chm_deadline_action late(const chm_deadline_info_t *info, void *arg) {
    (void)arg;
    printf("ctrl missed cycle %llu (deadline %llu us, now %llu us; %llu unhandled, %llu in all)\n",
           (unsigned long long)info->cycle, (unsigned long long)(info->deadline_ns / 1000),
           (unsigned long long)(info->now_ns / 1000), (unsigned long long)info->unhandled,
           (unsigned long long)info->misses);
    ++handled;
    return CHM_DL_ABORT_CYCLE; /* drop the late cycle; restart at the next release */
}

static void ctrl(void *arg) {
    (void)arg;
    while (cycle < 6) {
        int c = cycle++;
        chm_time_consume(c == 2 ? 3 * MS : MS / 2); /* cycle 2 overruns */
        if (chm_task_wait_period() != 0) return;
    }
}

static void background(void *arg) {
    (void)arg;
    chm_time_consume(10 * MS); /* aperiodic work: runs when ctrl does not */
}

int main(void) {
    chm_kernel_config_t cfg;
    chm_kernel_config_init(&cfg);
    cfg.policy = CHM_SCHED_MUF; /* or CHM_SCHED_RM, _EDF, _MLF, _FIXED */
    cfg.quantum_ns = MS;        /* round robin among equals */
    cfg.virtual_clock = 1;
    if (chm_kernel_init(&cfg) != 0) {
        printf("chm_kernel_init: %s\n", chm_err_last());
        return 1;
    }
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = "ctrl";
    a.period_ns = 4 * MS;
    a.deadline_ns = 2 * MS;
    a.wcet_ns = 1 * MS;
    a.critical = 1; /* MUF: always in the critical set */
    a.on_deadline = late;
    chm_tid_t id;
    if (chm_task_spawn(&id, ctrl, NULL, &a) != 0) {
        printf("spawn ctrl: %s\n", chm_err_last());
        return 1;
    }
    chm_task_attr_init(&a);
    a.name = "background";
    if (chm_task_spawn(NULL, background, NULL, &a) != 0) {
        printf("spawn background: %s\n", chm_err_last());
        return 1;
    }
    int r = chm_kernel_run();
    printf("policy %d, %d miss(es) handled\n", (int)chm_kernel_policy(), handled);
    chm_kernel_fini();
    return r != 0 || handled != 1;
}
