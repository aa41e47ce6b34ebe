/* RTPU 2 of the multi-RTPU demo: attaches the servo's shared state, starts
 * the logger (argv[1]) on RTPU 3 through express mail, then at 10 Hz
 * watches the servo, moves its set point every 2 s (shared memory under a
 * spin-lock) and after 5 s sends it a user signal (express mail again). */
#include <chimera/chimera.h>
#include <chimera/rtpu.h>
#include <chimera/shm.h>
#include <errno.h>
#include <stdio.h>
#include <string.h>

#include "multi.h"

#define MS 1000000ull

static servo_state_t *g_s;
static chm_tid_t g_servo = CHM_TID_NONE;

static void supervise(void *arg) {
    (void)arg;
    uint64_t last_cycles = 0;
    for (unsigned k = 1;; ++k) {
        servo_state_t seen;
        if (chm_spin_lock(&g_s->lock, 20000, 50 * MS) < 0) {
            printf("supervisor: the servo's lock stayed busy\n");
            chm_task_wait_period();
            continue;
        }
        seen = *g_s;
        if (k % 20 == 0) g_s->setpoint = -g_s->setpoint;
        (void)!chm_spin_unlock(&g_s->lock);
        if (k % 20 == 0) printf("supervisor: set point -> %+.1f\n", -seen.setpoint);
        if (k % 10 == 0) {
            printf("supervisor: t=%2us  servo position %+.3f (set point %+.1f, %s gains), %llu cycles/s, "
                   "worst lateness %.0f us\n",
                   k / 10, seen.position, seen.setpoint, seen.soft ? "soft" : "stiff",
                   (unsigned long long)(seen.cycles - last_cycles), (double)seen.worst_late_ns / 1e3);
            last_cycles = seen.cycles;
        }
        if (k == 50) {
            const int r = chm_rtpu_signal(1, g_servo, SERVO_SIG_SOFT);
            printf("supervisor: user signal %d to the servo (RTPU 1, task %d) by express mail: %s\n",
                   SERVO_SIG_SOFT, (int)g_servo, r ? chm_rtpu_last_error() : "delivered");
        }
        chm_task_wait_period();
    }
}

int main(int argc, char **argv) {
    if (argc < 2) {
        printf("supervisor: usage: supervisor.so LOGGER.so\n");
        return 1;
    }
    /* RTPU 1 may still be starting its servo: wait for it, bounded. */
    void *mem = NULL;
    int r = -ENOENT;
    for (int i = 0; i < 300 && r; ++i) {
        r = chm_shm_attach(SERVO_STATE, &mem, NULL);
        if (r == 0) r = chm_rtpu_find(1, "servo", &g_servo);
        if (r) chm_task_pause_until(chm_time_now() + 10 * MS);
    }
    if (r) {
        printf("supervisor: no servo on RTPU 1: %s\n", strerror(-r));
        return 1;
    }
    g_s = mem;
    const char *args[] = {argv[1]};
    chm_tid_t logger;
    r = chm_rtpu_spawn(3, argv[1], 1, args, &logger);
    if (r)
        printf("supervisor: cannot start the logger on RTPU 3: %s\n", chm_rtpu_last_error());
    else
        printf("supervisor: started %s on RTPU 3 (task %d) by express mail\n", argv[1], (int)logger);
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = "supervisor";
    a.period_ns = 100 * MS;
    a.wcet_ns = 5 * MS;
    chm_tid_t tid;
    if ((r = chm_task_spawn(&tid, supervise, NULL, &a)) != 0) {
        printf("supervisor: cannot spawn: %s\n", strerror(-r));
        return 1;
    }
    return 0;
}
