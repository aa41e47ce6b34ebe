/* RTPU 3 of the multi-RTPU demo, started there by the supervisor through
 * express mail: a task that blocks on the remote semaphore servo.tick,
 * which the servo on RTPU 1 Vs every 100 ms, and measures how long after
 * the V it woke (a cross-RTPU wake-up through the mailbox interrupt). */
#include <chimera/bp.h>
#include <chimera/chimera.h>
#include <chimera/rsem.h>
#include <chimera/shm.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "multi.h"

#define MS 1000000ull
#define MAX_TICKS 4096

static servo_state_t *g_s;
static chm_rsem_t *g_tick;
static uint64_t g_wake_ns[MAX_TICKS];
static unsigned g_n;

static int cmp(const void *a, const void *b) {
    const uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return x < y ? -1 : x > y;
}

/* p50 and max of the wake-ups so far (sorts a copy). */
static void figures(double *p50_us, double *p99_us, double *max_us) {
    static uint64_t s[MAX_TICKS];
    memcpy(s, g_wake_ns, g_n * sizeof s[0]);
    qsort(s, g_n, sizeof s[0], cmp);
    *p50_us = (double)s[g_n / 2] / 1e3;
    *p99_us = (double)s[(g_n * 99) / 100] / 1e3;
    *max_us = (double)s[g_n - 1] / 1e3;
}

static void log_task(void *arg) {
    (void)arg;
    for (;;) {
        const int r = chm_rsem_p_timed(g_tick, 1000 * MS);
        if (r == -ETIMEDOUT) {
            printf("logger: no tick from the servo for 1 s\n");
            continue;
        }
        if (r) {
            printf("logger: servo.tick: %s\n", strerror(-r));
            return;
        }
        const uint64_t v = g_s->tick_ns; /* written before the V we took */
        const uint64_t now = chm_time_now();
        if (g_n < MAX_TICKS && now >= v) g_wake_ns[g_n++] = now - v;
        if (g_n % 20 == 0 && g_n) {
            double p50, p99, max;
            figures(&p50, &p99, &max);
            printf("logger: %u ticks through servo.tick; wake-up after the V: p50 %.0f us, max %.0f us\n", g_n,
                   p50, max);
            (void)p99;
        }
    }
}

static void on_shutdown(void *arg) {
    (void)arg;
    if (!g_n) return;
    double p50, p99, max;
    figures(&p50, &p99, &max);
    printf("logger: shutdown hook: %u ticks received; remote semaphore wake-up p50 %.0f us, p99 %.0f us, "
           "max %.0f us\n", g_n, p50, p99, max);
}

int main(int argc, char **argv) {
    (void)argc;
    (void)argv;
    void *mem = NULL;
    int r = chm_shm_attach(SERVO_STATE, &mem, NULL);
    if (r == 0) r = chm_rsem_open(SERVO_TICK, &g_tick);
    if (r) {
        printf("logger: no servo to log: %s\n", strerror(-r));
        return 1;
    }
    g_s = mem;
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = "logger";
    a.priority = 10;
    chm_tid_t tid;
    if ((r = chm_task_spawn(&tid, log_task, NULL, &a)) != 0) return 1;
    if (chm_kernel_on_shutdown(on_shutdown, NULL) != 0) {
        printf("logger: %s\n", chm_err_last());
        return 1;
    }
    printf("logger: running on RTPU %d, waiting on %s\n", chm_bp_self(), SERVO_TICK);
    return 0;
}
