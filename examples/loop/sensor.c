/* RTPU 1 of the control-loop demo: a critical 1 kHz task that closes a
 * loop through another RTPU. Each cycle it samples a simulated unit mass,
 * sends the timestamped sample to the controller on RTPU 2 (loop.sense),
 * waits for the force it answers (loop.reply, at most 0.6 ms), applies it
 * and reports the cycle's figures to the host (loop.stats). See loop.h. */
#include <chimera/chimera.h>
#include <chimera/bp.h>
#include <chimera/msgq.h>
#include <errno.h>
#include <stdio.h>
#include <string.h>

#include "loop.h"

static chm_msgq_t *g_reply, *g_stats, *g_sense;
static uint64_t g_sent, g_answered, g_lost, g_unsent, g_stats_dropped, g_safe_cycles;
static int g_controller = -1; /* RTPU of the last answer */
static volatile uint32_t g_misses;
/* The stop: the shutdown hook asks (g_stop), the loop ends at the top of
 * its next cycle and sends no more; the hook joins it, so the counts it
 * prints are final. */
static volatile int g_stop;
static chm_tid_t g_loop = CHM_TID_NONE;

/* A late cycle runs on: the miss is counted and reported through
 * loop.stats, not printed 1000 times a second. */
static enum chm_deadline_action on_miss(const chm_deadline_info_t *info, void *arg) {
    (void)arg;
    g_misses = (uint32_t)info->misses;
    return CHM_DL_CONTINUE;
}

/* Records not yet handed to loop.stats, oldest first. A try send returns
 * at once when the monitor (an ordinary host process, which the OS may
 * deschedule while it holds the queue's lock) is inside a call, as when
 * the queue is full: the record then goes with the next cycle's, in order,
 * and only a backlog of STATS_BACKLOG records (the monitor not reading)
 * drops the oldest. */
#define STATS_BACKLOG 64
static loop_stat_t g_backlog[STATS_BACKLOG];
static unsigned g_backlog_first, g_backlog_n;

static void report(const loop_stat_t *st) {
    if (g_backlog_n == STATS_BACKLOG) { /* the oldest goes */
        g_backlog_first = (g_backlog_first + 1) % STATS_BACKLOG;
        --g_backlog_n;
        ++g_stats_dropped;
    }
    g_backlog[(g_backlog_first + g_backlog_n++) % STATS_BACKLOG] = *st;
    while (g_backlog_n && chm_msgq_try_send(g_stats, 0, 0, &g_backlog[g_backlog_first], sizeof *st) == 0) {
        g_backlog_first = (g_backlog_first + 1) % STATS_BACKLOG;
        --g_backlog_n;
    }
}

/* Wait for the answer to `seq` until `until_ns`; older answers (to a
 * sample whose wait already ran out) are dropped. 1: *out holds it. */
static int await_reply(uint64_t seq, uint64_t until_ns, loop_reply_t *out) {
    for (;;) {
        chm_msgq_msg_info_t info;
        /* An absolute deadline: the drops and retries below all count
         * against the same instant; one already past does not wait. */
        const int n = chm_msgq_receive_until(g_reply, out, sizeof *out, &info, until_ns);
        if (n == (int)sizeof *out && out->seq == seq) {
            g_controller = info.sender;
            return 1;
        }
        if (n < 0 && n != -EINTR) return 0;
    }
}

/* Why the controller went silent, for the line that says the sensor went
 * to its safe output: its RTPU's state on the backplane. */
static const char *controller_state(void) {
    static chm_bp_status_t st; /* large: not on the task's stack */
    if (g_controller < 0) return "never answered";
    if (chm_bp_status(&st) != 0) return "state unknown";
    switch (st.slot[g_controller].state) {
    case CHM_BP_RUNNING: return "still running, not answering in time";
    case CHM_BP_DEAD:
    case CHM_BP_RECOVERING: return "died without leaving the backplane (killed or crashed)";
    case CHM_BP_FREE:
    case CHM_BP_LEAVING: return "left the backplane (stopped)";
    default: return "joining";
    }
}

static void sensor(void *arg) {
    (void)arg;
    const double dt = LOOP_PERIOD_NS / 1e9;
    double pos = 0.0, vel = 0.0;
    unsigned silent = 0; /* cycles in a row without an answer */
    int safe = 0;        /* 1: at the safe output */
    for (uint64_t seq = 1;; ++seq) {
        if (g_stop) return;
        const uint64_t release = chm_task_cycle_release();
        const uint64_t t0 = chm_time_now();
        loop_stat_t st = {.seq = seq, .release_late_ns = (uint32_t)(t0 - release)};
        /* The controller creates loop.sense; until it has, the sample waits. */
        if (!g_sense && chm_msgq_open(LOOP_SENSE, &g_sense) != 0) g_sense = NULL;
        const loop_sample_t s = {seq, t0, (float)pos, (float)vel};
        double force = 0.0;
        int answered = 0;
        if (g_sense && chm_msgq_try_send(g_sense, 1, 0, &s, sizeof s) == 0) {
            ++g_sent;
            loop_reply_t r;
            if (await_reply(seq, t0 + LOOP_REPLY_WAIT_NS, &r)) {
                ++g_answered;
                answered = 1;
                force = r.force;
                st.one_way_ns = (uint32_t)(r.received_ns - t0);
                st.round_trip_ns = (uint32_t)(chm_time_now() - t0);
            } else {
                ++g_lost;
            }
        } else {
            ++g_unsent;
        }
        /* Fail safe: after LOOP_SAFE_AFTER silent cycles the plant gets no
         * force until the controller answers again. */
        silent = answered ? 0 : silent + 1;
        if (answered && safe) {
            safe = 0;
            printf("sensor: cycle %llu: the controller on RTPU %d answers again: loop closed\n",
                   (unsigned long long)seq, g_controller);
        } else if (!safe && silent >= LOOP_SAFE_AFTER) {
            safe = 1;
            printf("sensor: cycle %llu: no answer for %u cycles, controller RTPU %d %s: "
                   "safe output (force 0)\n",
                   (unsigned long long)seq, silent, g_controller, controller_state());
        }
        if (safe) {
            force = 0.0;
            ++g_safe_cycles;
        }
        st.safe = (uint32_t)safe;
        st.controller = g_controller;
        vel += force * dt; /* the plant: a unit mass pushed by the force */
        pos += vel * dt;
        st.misses = g_misses;
        st.lost = (uint32_t)g_lost;
        st.unsent = (uint32_t)g_unsent;
        st.position = (float)pos;
        st.setpoint = loop_setpoint(seq);
        report(&st); /* no monitor reading: records are dropped, the loop goes on */
        chm_task_wait_period();
    }
}

static void on_shutdown(void *arg) {
    (void)arg;
    chm_task_status_t ts;
    /* The hook runs above the loop's priority; the loop sees the request
     * within a cycle or two (bounded: a wedged loop does not hold the stop). */
    g_stop = 1;
    if (chm_task_join(g_loop, 20 * LOOP_PERIOD_NS, &ts) == 0 || chm_task_status(g_loop, &ts) == 0)
        printf("sensor: shutdown hook: %llu cycles, %llu samples sent, %llu answered, %llu answers lost, "
               "%llu not sent, %llu deadline misses, %llu stats records dropped, %llu cycles at the safe output\n",
               (unsigned long long)ts.cycles, (unsigned long long)g_sent, (unsigned long long)g_answered,
               (unsigned long long)g_lost, (unsigned long long)g_unsent, (unsigned long long)ts.misses,
               (unsigned long long)g_stats_dropped, (unsigned long long)g_safe_cycles);
    (void)!chm_msgq_destroy(LOOP_REPLY);
    (void)!chm_msgq_destroy(LOOP_STATS);
}

int main(int argc, char **argv) {
    (void)argc;
    (void)argv;
    if (loop_queue("sensor", LOOP_REPLY, sizeof(loop_reply_t), 16, chm_bp_self(), &g_reply) ||
        loop_queue("sensor", LOOP_STATS, sizeof(loop_stat_t), LOOP_STATS_CAPACITY, CHM_MSGQ_COMMON, &g_stats))
        return 1;
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = "sensor";
    a.period_ns = LOOP_PERIOD_NS;
    a.wcet_ns = LOOP_PERIOD_NS * 7 / 10;
    a.critical = 1;
    a.on_deadline = on_miss;
    a.joinable = 1; /* the shutdown hook joins it */
    const int r = chm_task_spawn(&g_loop, sensor, NULL, &a);
    if (r) {
        printf("sensor: cannot spawn the loop: %s\n", strerror(-r));
        return 1;
    }
    if (chm_kernel_on_shutdown(on_shutdown, NULL) != 0) {
        printf("sensor: %s\n", chm_err_last());
        return 1;
    }
    printf("sensor: 1 kHz loop on RTPU %d (task %d): samples to %s, answers on %s, figures on %s\n",
           chm_bp_self(), (int)g_loop, LOOP_SENSE, LOOP_REPLY, LOOP_STATS);
    return 0;
}
