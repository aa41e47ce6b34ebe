/* docs/examples/sem_signals.c */
#include <errno.h>
#include <stdio.h>

#include "chimera/chimera.h"

#define MS 1000000ull

static chm_sem_t items;   /* counting: samples ready */
static chm_sem_t guard;   /* binary with priority inheritance: a mutex */
static chm_sem_t never;   /* nobody gives it: a wait a signal interrupts */
static double buffer[4];
static int failed;

static void producer(void *arg) {
    (void)arg;
    for (int i = 0; i < 4; ++i) {
        if (chm_task_pause_until(chm_time_now() + MS) != 0 || chm_sem_p(&guard) != 0) {
            failed = 1;
            return;
        }
        buffer[i] = i * 0.5;
        if (chm_sem_v(&guard) != 0 || chm_sem_v(&items) != 0) { /* wakes the consumer */
            failed = 1;
            return;
        }
    }
}

static void consumer(void *arg) {
    (void)arg;
    for (int i = 0; i < 4; ++i) {
        int r = chm_sem_p_timed(&items, 10 * MS); /* relative timeout */
        if (r != 0) {
            printf("chm_sem_p_timed: %d %s\n", r, chm_err_last());
            failed = 1;
            return;
        }
        chm_task_lock(); /* no preemption: keep this short */
        double v = buffer[i];
        chm_task_unlock();
        printf("sample %d = %.1f\n", i, v);
    }
}

static void on_signal(int signo, void *arg) {
    (void)arg;
    printf("waiter got user signal %d\n", signo);
}

static void waiter(void *arg) {
    (void)arg;
    if (chm_usig_handle(1, on_signal, NULL) != 0) { failed = 1; return; }
    int r = chm_sem_p(&never); /* blocks until the signal */
    printf("chm_sem_p returned %s\n", r == -EINTR ? "-EINTR" : "something else");
    if (r != -EINTR) failed = 1;
}

static void signaller(void *arg) {
    if (chm_task_pause_until(chm_time_now() + 2 * MS) != 0 ||
        chm_usig_send(*(chm_tid_t *)arg, 1) != 0) {
        printf("chm_usig_send: %s\n", chm_err_last());
        failed = 1;
    }
}

static int spawn(chm_tid_t *id, void (*fn)(void *), void *arg, const char *name, int prio) {
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = name;
    a.priority = prio;
    if (chm_task_spawn(id, fn, arg, &a) != 0) {
        printf("spawn %s: %s\n", name, chm_err_last());
        return -1;
    }
    return 0;
}

int main(void) {
    chm_kernel_config_t cfg;
    chm_kernel_config_init(&cfg);
    cfg.virtual_clock = 1;
    if (chm_kernel_init(&cfg) != 0 || chm_sem_init(&items, CHM_SEM_COUNTING, 0, 0) != 0 ||
        chm_sem_init(&guard, CHM_SEM_BINARY, 1, CHM_SEM_INHERIT) != 0 ||
        chm_sem_init(&never, CHM_SEM_BINARY, 0, 0) != 0) {
        printf("init: %s\n", chm_err_last());
        return 1;
    }
    chm_tid_t w;
    if (spawn(NULL, producer, NULL, "producer", 1) || spawn(NULL, consumer, NULL, "consumer", 2) ||
        spawn(&w, waiter, NULL, "waiter", 3) || spawn(NULL, signaller, &w, "signaller", 3))
        return 1;
    int r = chm_kernel_run();
    if (chm_sem_destroy(&items) != 0 || chm_sem_destroy(&guard) != 0 ||
        chm_sem_destroy(&never) != 0)
        failed = 1;
    chm_kernel_fini();
    return r != 0 || failed;
}
