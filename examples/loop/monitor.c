/* chimera-loop-monitor: the host side of the control-loop demo. An
 * ordinary process that attaches to the backplane as a host RTPU, drains
 * loop.stats (blocking on its futex) and prints the loop's figures once a
 * second: samples sent and answered, one-way and round-trip latency p50
 * and p99, the sensor's release lateness, deadline misses, lost answers.
 *
 * usage: chimera-loop-monitor [--backplane PATH] [--seconds N]
 * It also watches the RTPUs that were running when it started: one that
 * dies or leaves is named at once, with how (died without leaving the
 * backplane, i.e. killed or crashed, or left it).
 * Exit status 0 when the loop ran and every record arrived once, in order;
 * 1 when the loop broke (an RTPU died or left, a whole second without an
 * answer, the sensor at its safe output), stopped or records were lost; 2
 * bad usage or no such system. */
#include <chimera/bp.h>
#include <chimera/msgq.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "loop.h"

#define WINDOW_MAX 65536 /* records whose figures a window keeps */

static uint64_t now_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000000u + (uint64_t)ts.tv_nsec;
}

static int by_value(const void *a, const void *b) {
    const uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
    return (x > y) - (x < y);
}

/* The q-quantile of v[0..n) in µs (sorts v); 0 when n is 0. */
static double quantile_us(uint32_t *v, size_t n, double q) {
    if (n == 0) return 0;
    qsort(v, n, sizeof *v, by_value);
    size_t i = (size_t)(q * (double)(n - 1) + 0.5);
    return v[i] / 1e3;
}

/* One window's records (a second, or the whole run). */
typedef struct window {
    size_t records, answered;
    uint32_t one_way[WINDOW_MAX], round_trip[WINDOW_MAX], late[WINDOW_MAX];
} window_t;

static void add(window_t *w, const loop_stat_t *st) {
    ++w->records;
    if (w->records > WINDOW_MAX) return; /* figures from the first WINDOW_MAX */
    w->late[w->records - 1] = st->release_late_ns;
    if (st->round_trip_ns) {
        w->one_way[w->answered] = st->one_way_ns;
        w->round_trip[w->answered] = st->round_trip_ns;
        ++w->answered;
    }
}

/* The RTPUs running when the monitor started (their generation: a slot
 * joined again by a new process is another RTPU), and which of them were
 * already reported gone. */
static chm_bp_status_t g_start, g_now;
static int g_gone[CHM_BP_MAX_SLOTS];

static int watched(uint32_t s) {
    return g_start.slot[s].kind == CHM_BP_KIND_RTPU && g_start.slot[s].state == CHM_BP_RUNNING &&
           (int)s != g_start.self;
}

/* Report each watched RTPU that is no longer the one that was running;
 * the number newly reported. */
static int report_gone(void) {
    if (chm_bp_status(&g_now) != 0) return 0;
    int n = 0;
    for (uint32_t s = 0; s < g_start.slots; ++s) {
        if (!watched(s) || g_gone[s]) continue;
        const chm_bp_slot_info_t *was = &g_start.slot[s], *is = &g_now.slot[s];
        if (is->state == CHM_BP_RUNNING && is->generation == was->generation) continue;
        const char *how;
        if (is->generation != was->generation) how = "was replaced by a new process";
        else if (is->state == CHM_BP_DEAD || is->state == CHM_BP_RECOVERING)
            how = "died without leaving the backplane (killed or crashed); the backplane recovered it";
        else how = "left the backplane (stopped)";
        printf("chimera-loop-monitor: RTPU %u (%s, pid %d) %s\n", s, was->name, (int)was->pid, how);
        g_gone[s] = 1;
        ++n;
    }
    fflush(stdout);
    return n;
}

static void usage(const char *why) {
    fprintf(stderr, "chimera-loop-monitor: %s\nusage: chimera-loop-monitor [--backplane PATH] [--seconds N]\n", why);
    exit(2);
}

int main(int argc, char **argv) {
    char path[512];
    int seconds = 10;
    if (chm_bp_default_path(path, sizeof path) != 0) usage("the default backplane path is too long");
    for (int i = 1; i < argc; ++i) {
        if (!strcmp(argv[i], "--backplane") && i + 1 < argc) {
            snprintf(path, sizeof path, "%s", argv[++i]);
        } else if (!strcmp(argv[i], "--seconds") && i + 1 < argc) {
            char *end;
            long v = strtol(argv[++i], &end, 10);
            if (*end || v < 1 || v > 3600) usage("--seconds wants 1..3600");
            seconds = (int)v;
        } else {
            usage("unknown argument");
        }
    }
    int r = chm_bp_attach_host(path, "loop-monitor", NULL);
    if (r) {
        fprintf(stderr, "chimera-loop-monitor: %s: %s\n", path, chm_bp_last_error());
        return 2;
    }
    /* The sensor creates loop.stats when its program starts: wait up to 10 s. */
    chm_msgq_t *q = NULL;
    for (uint64_t give_up = now_ns() + 10000000000u; (r = chm_msgq_open(LOOP_STATS, &q)) == -ENOENT;) {
        if (now_ns() > give_up) break;
        nanosleep(&(struct timespec){0, 20000000}, NULL);
    }
    if (r) {
        fprintf(stderr, "chimera-loop-monitor: no queue %s on %s: %s (is the sensor running?)\n", LOOP_STATS, path,
                r == -ENOENT ? "not created within 10 s" : chm_bp_last_error());
        return 2;
    }
    (void)!chm_bp_status(&g_start);
    /* Records queued before we came are history: start from the newest. */
    loop_stat_t st, prev = {0};
    while (chm_msgq_try_receive(q, &st, sizeof st, NULL) == (int)sizeof st) prev = st;
    const loop_stat_t base = prev; /* the summary counts from here */

    static window_t sec, all;
    uint64_t gaps = 0, first = 0;
    int status = 0, gone = 0, silent_seconds = 0, safe_seen = 0;
    printf("   t   sent/s  answered/s   one-way p50     p99   round trip p50     p99   lateness p99"
           "   misses  lost  position\n");
    const uint64_t start = now_ns();
    for (int t = 1; t <= seconds; ++t) {
        const uint64_t end = start + (uint64_t)t * 1000000000u;
        memset(&sec, 0, sizeof sec);
        loop_stat_t last = prev;
        for (uint64_t now; (now = now_ns()) < end;) {
            r = chm_msgq_receive_timed(q, &st, sizeof st, NULL, end - now);
            if (r == -ETIMEDOUT || r == -EINTR) continue;
            if (r == -EIDRM) {
                printf("chimera-loop-monitor: %s was destroyed: the sensor stopped\n", LOOP_STATS);
                seconds = t;
                break;
            }
            if (r != (int)sizeof st) {
                fprintf(stderr, "chimera-loop-monitor: receive from %s: %s\n", LOOP_STATS, chm_bp_last_error());
                return 1;
            }
            if (!first) first = st.seq;
            if (last.seq && st.seq != last.seq + 1) gaps += st.seq - last.seq - 1;
            add(&sec, &st);
            add(&all, &st);
            last = st;
        }
        const uint32_t misses = last.misses - prev.misses, lost = last.lost - prev.lost;
        gone += report_gone();
        if (sec.records && !sec.answered) ++silent_seconds;
        if (last.safe) safe_seen = 1;
        printf("%3d s %7zu %11zu %10.0f us %6.0f us %13.0f us %6.0f us %11.0f us %8u %5u %+9.3f%s\n", t, sec.records,
               sec.answered, quantile_us(sec.one_way, sec.answered, 0.5), quantile_us(sec.one_way, sec.answered, 0.99),
               quantile_us(sec.round_trip, sec.answered, 0.5), quantile_us(sec.round_trip, sec.answered, 0.99),
               quantile_us(sec.late, sec.records < WINDOW_MAX ? sec.records : WINDOW_MAX, 0.99), misses, lost,
               last.position, last.safe ? "  SAFE OUTPUT" : "");
        fflush(stdout);
        if (sec.records == 0) {
            fprintf(stderr, "chimera-loop-monitor: no record from the sensor in second %d: the loop stopped\n", t);
            status = 1;
            break;
        }
        prev = last;
    }
    size_t n = all.answered < WINDOW_MAX ? all.answered : WINDOW_MAX;
    gone += report_gone();
    printf("summary: %zu cycles in %d s, %zu answered in time, %zu unanswered (%u answers lost, %u samples not "
           "sent), %u deadline misses; round trip p50 %.0f us p99 %.0f us (first %zu answers)\n",
           all.records, seconds, all.answered, all.records - all.answered, prev.lost - base.lost,
           prev.unsent - base.unsent, prev.misses - base.misses, quantile_us(all.round_trip, n, 0.5),
           quantile_us(all.round_trip, n, 0.99), n);
    /* A loop that broke is a failed run, however many records arrived. */
    if (gone || silent_seconds || safe_seen) {
        printf("the loop broke:");
        if (gone) printf(" %d RTPU%s gone (above);", gone, gone == 1 ? "" : "s");
        if (silent_seconds) printf(" %d second%s without any answer;", silent_seconds, silent_seconds == 1 ? "" : "s");
        if (safe_seen) printf(" the sensor went to its safe output;");
        printf("\n");
        status = 1;
    }
    if (gaps) {
        printf("records: %llu of the sensor's cycles never reached the monitor\n", (unsigned long long)gaps);
        status = 1;
    } else if (all.records) {
        printf("records: cycles %llu..%llu, each received once and in order\n", (unsigned long long)first,
               (unsigned long long)prev.seq);
    }
    (void)!chm_msgq_close(q);
    (void)!chm_bp_leave();
    return status;
}
