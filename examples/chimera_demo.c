/* The single-RTPU kernel demo (`make demo`): a 1 kHz servo loop, a 100 Hz
 * supervisor and a background logger share one RTPU under MUF; once a second
 * the monitor prints how each keeps its period. Runs about 5 seconds. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

#include "chimera/chimera.h"

#define MS 1000000ull

static volatile double g_position, g_command = 1.0;
static uint64_t g_servo_late_max, g_servo_cycles;
static chm_sem_t g_new_setpoint;

/* 1 kHz: a PD loop on a simulated unit mass, measuring its own release
 * lateness (how long after its release it started). */
static void servo(void *arg) {
    (void)arg;
    double vel = 0, prev_err = 0;
    for (;;) {
        uint64_t late = chm_time_now() - chm_task_cycle_release();
        if (late > g_servo_late_max) g_servo_late_max = late;
        double err = g_command - g_position;
        double torque = 400.0 * err + 40.0 * (err - prev_err) / 0.001;
        prev_err = err;
        vel += torque * 0.001;
        g_position += vel * 0.001;
        g_servo_cycles++;
        chm_task_wait_period();
    }
}

/* 100 Hz: changes the set point every second and wakes the logger. */
static void supervisor(void *arg) {
    (void)arg;
    for (int i = 0;; ++i) {
        if (i % 100 == 99) {
            g_command = -g_command;
            (void)!chm_sem_v(&g_new_setpoint);
        }
        chm_task_wait_period();
    }
}

/* Background: aperiodic, lowest urgency, prints through plain printf. */
static void logger(void *arg) {
    (void)arg;
    for (;;) {
        if (chm_sem_p(&g_new_setpoint) == 0)
            printf("  logger: new set point %+.1f (position %+.3f)\n", g_command, g_position);
    }
}

static void monitor(void *arg) {
    chm_tid_t *ids = arg;
    const char *names[] = {"servo", "supervisor", "logger"};
    for (int s = 1; s <= 5; ++s) {
        chm_task_pause_until(chm_time_now() + 1000 * MS);
        printf("t=%ds  %-10s %8s %8s %10s %10s\n", s, "task", "cycles", "misses", "cpu ms", "stack B");
        for (int i = 0; i < 3; ++i) {
            chm_task_status_t st;
            if (chm_task_status(ids[i], &st) != 0) continue;
            printf("      %-10s %8llu %8llu %10.1f %10zu\n", names[i], (unsigned long long)st.cycles,
                   (unsigned long long)st.misses, st.cpu_ns / 1e6, st.stack_high_water);
        }
        printf("      servo worst release lateness %.1f us over %llu cycles\n",
               g_servo_late_max / 1e3, (unsigned long long)g_servo_cycles);
        fflush(stdout);
    }
    chm_kernel_stop(0);
}

static void spawn(chm_tid_t *id, void (*fn)(void *), void *arg, const char *name, uint64_t period,
                  uint64_t wcet, int prio) {
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = name;
    a.period_ns = period;
    a.wcet_ns = wcet;
    a.priority = prio;
    int e = chm_task_spawn(id, fn, arg, &a);
    if (e) {
        fprintf(stderr, "chimera-demo: cannot spawn %s: error %d\n", name, e);
        exit(1);
    }
}

int main(void) {
    chm_kernel_config_t cfg;
    chm_kernel_config_init(&cfg); /* MUF, 1 ms quantum */
    if (chm_kernel_init(&cfg) != 0) {
        fprintf(stderr, "chimera-demo: kernel init failed\n");
        return 1;
    }
    if (chm_sem_init(&g_new_setpoint, CHM_SEM_COUNTING, 0, 0) != 0) return 1;
    static chm_tid_t ids[3];
    chm_tid_t mon;
    printf("Chimera single-RTPU demo: 1 kHz servo, 100 Hz supervisor, background logger (MUF)\n");
    spawn(&ids[0], servo, NULL, "servo", 1 * MS, 200000, 0);
    spawn(&ids[1], supervisor, NULL, "supervisor", 10 * MS, 100000, 0);
    spawn(&ids[2], logger, NULL, "logger", 0, 0, 0);
    spawn(&mon, monitor, ids, "monitor", 0, 0, 10);
    int r = chm_kernel_run();
    printf("demo finished (%d); servo cycles %llu\n", r, (unsigned long long)g_servo_cycles);
    chm_kernel_fini();
    return r;
}
