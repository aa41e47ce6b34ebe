/* stall_witness: how long this host kept real-time work off its CPUs while
 * a test ran. One thread per usable CPU, pinned, at SCHED_FIFO --priority
 * (above the RTPUs under test, so only the host or higher-priority work can
 * delay it; SCHED_OTHER when FIFO is not allowed, said in its report),
 * wakes on a 1 ms grid (absolute clock_nanosleep) and records how late
 * each wake-up was. A wake-up at least --threshold-us late is a stall of
 * that length. On SIGTERM/SIGINT (or after --seconds) it prints one line:
 *   stall_witness: fifo=1 cpus=2 wakeups=N stalls=S max_us=M excusable=E
 * where E bounds the deadline misses the stalls can explain for one module
 * of period --period-us: a stall of L delays at most L / period + 2 of its
 * cycles past their deadlines (the cycle it hits, the ones it covers, the
 * one after). Exit 0, or 2 on bad usage. */
#define _GNU_SOURCE
#include <errno.h>
#include <pthread.h>
#include <sched.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#define MAX_CPUS 64

static atomic_int g_stop;
static int g_priority = 51;
static uint64_t g_threshold_ns = 200000, g_period_ns = 2000000;
static int g_fifo = 1;

typedef struct {
    int cpu;
    uint64_t wakeups, stalls, max_ns, excusable;
} witness_t;

static uint64_t now_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000000u + (uint64_t)ts.tv_nsec;
}

static void* watch(void* arg) {
    witness_t* w = arg;
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(w->cpu, &set);
    (void)pthread_setaffinity_np(pthread_self(), sizeof set, &set);
    uint64_t next = now_ns();
    while (!atomic_load(&g_stop)) {
        next += 1000000;
        const struct timespec at = {(time_t)(next / 1000000000u), (long)(next % 1000000000u)};
        while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &at, NULL) == EINTR && !atomic_load(&g_stop)) {
        }
        const uint64_t t = now_ns(), late = t > next ? t - next : 0;
        ++w->wakeups;
        if (late > w->max_ns) w->max_ns = late;
        if (late >= g_threshold_ns) {
            ++w->stalls;
            w->excusable += late / g_period_ns + 2;
        }
        if (t > next + 1000000) next = t - t % 1000000;  // a long stall: back on the grid, no burst of catch-ups
    }
    return NULL;
}

static void on_signal(int sig) {
    (void)sig;
    atomic_store(&g_stop, 1);
}

static void usage(const char* why) {
    fprintf(stderr, "stall_witness: %s\nusage: stall_witness [--priority P] [--threshold-us T] [--period-us T] "
                    "[--seconds S]\n", why);
    exit(2);
}

int main(int argc, char** argv) {
    double seconds = 3600;
    for (int i = 1; i < argc; ++i) {
        if (i + 1 >= argc) usage("an option lacks its value");
        char* end;
        const double v = strtod(argv[++i], &end);
        if (*end || !(v > 0)) usage("values are positive numbers");
        if (!strcmp(argv[i - 1], "--priority")) g_priority = (int)v;
        else if (!strcmp(argv[i - 1], "--threshold-us")) g_threshold_ns = (uint64_t)(v * 1000);
        else if (!strcmp(argv[i - 1], "--period-us")) g_period_ns = (uint64_t)(v * 1000);
        else if (!strcmp(argv[i - 1], "--seconds")) seconds = v;
        else usage("unknown option");
    }
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sigaction(SIGTERM, &sa, NULL);
    sigaction(SIGINT, &sa, NULL);
    const struct sched_param sp = {.sched_priority = g_priority};
    if (sched_setscheduler(0, SCHED_FIFO, &sp) != 0) g_fifo = 0;  // threads inherit it
    cpu_set_t allowed;
    CPU_ZERO(&allowed);
    (void)sched_getaffinity(0, sizeof allowed, &allowed);
    static witness_t w[MAX_CPUS];
    pthread_t th[MAX_CPUS];
    int n = 0;
    for (int c = 0; c < CPU_SETSIZE && n < MAX_CPUS; ++c)
        if (CPU_ISSET(c, &allowed)) {
            w[n].cpu = c;
            if (pthread_create(&th[n], NULL, watch, &w[n]) != 0) break;
            ++n;
        }
    const uint64_t end = now_ns() + (uint64_t)(seconds * 1e9);
    while (!atomic_load(&g_stop) && now_ns() < end) usleep(20000);
    atomic_store(&g_stop, 1);
    witness_t all = {0};
    for (int i = 0; i < n; ++i) {
        pthread_join(th[i], NULL);
        all.wakeups += w[i].wakeups;
        all.stalls += w[i].stalls;
        all.excusable += w[i].excusable;
        if (w[i].max_ns > all.max_ns) all.max_ns = w[i].max_ns;
    }
    printf("stall_witness: fifo=%d cpus=%d wakeups=%llu stalls=%llu max_us=%llu excusable=%llu\n", g_fifo, n,
           (unsigned long long)all.wakeups, (unsigned long long)all.stalls, (unsigned long long)(all.max_ns / 1000),
           (unsigned long long)all.excusable);
    return 0;
}
