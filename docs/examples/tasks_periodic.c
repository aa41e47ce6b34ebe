/* docs/examples/tasks_periodic.c */
#include <stdio.h>

#include "chimera/chimera.h"

#define MS 1000000ull

static chm_task_key_t cycles_key;
static int failed;

static void on_end(void *arg) {
    printf("%s ended\n", (const char *)arg);
}

static void servo(void *arg) {
    (void)arg;
    int count = 0; /* lives on this task's stack while it runs */
    if (chm_task_set_local(cycles_key, &count) != 0 || chm_task_on_end(on_end, "servo") != 0) {
        printf("servo setup: %s\n", chm_err_last());
        failed = 1;
        return;
    }
    for (int i = 0; i < 10; ++i) {
        chm_time_consume(200000); /* the cycle's work: 0.2 ms of CPU */
        ++*(int *)chm_task_get_local(cycles_key);
        if (i == 4) { /* slow down to 200 Hz from the next release on */
            chm_task_timing_t t = {.period_ns = 5 * MS, .deadline_ns = 0, .wcet_ns = MS};
            if (chm_task_set_timing(chm_task_self(), &t) != 0) {
                printf("chm_task_set_timing: %s\n", chm_err_last());
                failed = 1;
                return;
            }
        }
        if (chm_task_wait_period() != 0) { /* absolute releases: no drift */
            printf("chm_task_wait_period: %s\n", chm_err_last());
            failed = 1;
            return;
        }
    }
    chm_task_end(count); /* the status chm_task_join reports */
}

static void supervisor(void *arg) {
    chm_tid_t servo_id = *(chm_tid_t *)arg;
    chm_task_status_t st;
    int r = chm_task_join(servo_id, CHM_FOREVER, &st);
    if (r != 0) {
        printf("chm_task_join: %s\n", chm_err_last());
        failed = 1;
        return;
    }
    printf("servo: %llu cycles, %llu misses, exit status %d, at %llu ms\n",
           (unsigned long long)st.cycles, (unsigned long long)st.misses, st.exit_status,
           (unsigned long long)(chm_time_now() / MS));
    if (st.exit_status != 10 || st.misses != 0) failed = 1;
}

int main(void) {
    chm_kernel_config_t cfg;
    chm_kernel_config_init(&cfg);
    cfg.virtual_clock = 1; /* time advances only as tasks consume it */
    if (chm_kernel_init(&cfg) != 0 || chm_task_key_create(&cycles_key, NULL) != 0) {
        printf("init: %s\n", chm_err_last());
        return 1;
    }
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = "servo";
    a.period_ns = 1 * MS;     /* 1 kHz */
    a.deadline_ns = 1 * MS;   /* relative; 0 would mean the period */
    a.wcet_ns = 300000;       /* estimated worst case per cycle */
    a.joinable = 1;
    chm_tid_t servo_id;
    if (chm_task_spawn(&servo_id, servo, NULL, &a) != 0) {
        printf("spawn servo: %s\n", chm_err_last());
        return 1;
    }
    chm_task_attr_init(&a);
    a.name = "supervisor";
    if (chm_task_spawn(NULL, supervisor, &servo_id, &a) != 0) {
        printf("spawn supervisor: %s\n", chm_err_last());
        return 1;
    }
    int r = chm_kernel_run(); /* until every task has ended */
    chm_kernel_fini();
    return r != 0 || failed;
}
