/* RTPU 1 of the multi-RTPU demo: a 1 kHz servo loop (PD control of a
 * simulated unit mass) that reads its set point from global shared memory
 * and publishes its state there under a spin-lock; every 100 cycles it Vs
 * the remote semaphore servo.tick, which wakes a task on another RTPU.
 * User signal 1 (sent from RTPU 2 by express mail) toggles its gains. */
#include <chimera/chimera.h>
#include <chimera/bp.h>
#include <chimera/rsem.h>
#include <chimera/shm.h>
#include <errno.h>
#include <stdio.h>
#include <string.h>

#include "multi.h"

#define MS 1000000ull

static servo_state_t *g_s;
static chm_rsem_t *g_tick;
static volatile int g_soft;

static void on_signal(int signo, void *arg) {
    (void)arg;
    g_soft = !g_soft;
    printf("servo: user signal %d: %s gains\n", signo, g_soft ? "soft" : "stiff");
}

static void servo(void *arg) {
    (void)arg;
    if (chm_usig_handle(SERVO_SIG_SOFT, on_signal, NULL) != 0) {
        printf("servo: %s\n", chm_err_last());
        return;
    }
    double pos = 0, vel = 0;
    uint64_t cycles = 0, worst = 0;
    for (;;) {
        const uint64_t now = chm_time_now();
        const uint64_t late = now - chm_task_cycle_release();
        if (late > worst) worst = late;
        /* Bounded: a stuck peer costs this cycle its exchange, never the loop. */
        const int locked = chm_spin_lock(&g_s->lock, 2000, 200000);
        const double setpoint = g_s->setpoint;
        const double kp = g_soft ? 100.0 : 900.0, kd = g_soft ? 8.0 : 50.0;
        const double force = kp * (setpoint - pos) - kd * vel;
        vel += force * 0.001;
        pos += vel * 0.001;
        ++cycles;
        if (locked == 0 || locked == -EOWNERDEAD) {
            g_s->position = pos;
            g_s->velocity = vel;
            g_s->cycles = cycles;
            g_s->worst_late_ns = worst;
            g_s->soft = g_soft;
            (void)!chm_spin_unlock(&g_s->lock);
        }
        if (cycles % 100 == 0) {
            g_s->tick_ns = chm_time_now(); /* ordered before the V by the semaphore's lock */
            (void)!chm_rsem_v(g_tick);
        }
        chm_task_wait_period();
    }
}

static void on_shutdown(void *arg) {
    (void)arg;
    chm_tid_t me;
    chm_task_status_t st;
    if (chm_task_find("servo", &me) == 0 && chm_task_status(me, &st) == 0)
        printf("servo: shutdown hook: %llu cycles, %llu deadline misses, worst release lateness %.0f us\n",
               (unsigned long long)st.cycles, (unsigned long long)st.misses, (double)g_s->worst_late_ns / 1e3);
    (void)!chm_shm_destroy(SERVO_STATE); /* the names go; attached peers keep the memory */
    (void)!chm_rsem_destroy(SERVO_TICK);
}

int main(int argc, char **argv) {
    (void)argc;
    (void)argv;
    void *mem = NULL;
    int r = chm_shm_create(SERVO_STATE, sizeof(servo_state_t), chm_bp_self(), &mem);
    if (r == -EEXIST) r = chm_shm_attach(SERVO_STATE, &mem, NULL); /* an RTPU restarted */
    if (r) {
        printf("servo: cannot create %s: %s\n", SERVO_STATE, chm_bp_last_error());
        return 1;
    }
    g_s = mem;
    if (chm_spin_init(&g_s->lock) != 0) {
        printf("servo: %s\n", chm_err_last());
        return 1;
    }
    g_s->setpoint = 1.0;
    r = chm_rsem_create(SERVO_TICK, CHM_SEM_COUNTING, 0, -1, &g_tick);
    if (r == -EEXIST) r = chm_rsem_open(SERVO_TICK, &g_tick);
    if (r) {
        printf("servo: cannot create %s: %s\n", SERVO_TICK, chm_bp_last_error());
        return 1;
    }
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = "servo";
    a.period_ns = 1 * MS;
    a.wcet_ns = MS / 10;
    a.critical = 1;
    chm_tid_t tid;
    if ((r = chm_task_spawn(&tid, servo, NULL, &a)) != 0) {
        printf("servo: cannot spawn the loop: %s\n", strerror(-r));
        return 1;
    }
    if (chm_kernel_on_shutdown(on_shutdown, NULL) != 0) {
        printf("servo: %s\n", chm_err_last());
        return 1;
    }
    printf("servo: 1 kHz loop running on RTPU %d (task %lld); state in %s, tick on %s\n", chm_bp_self(), (long long)tid,
           SERVO_STATE, SERVO_TICK);
    return 0;
}
