/* RTPU 2 of the control-loop demo: a task blocked on loop.sense wakes for
 * each sample the sensor on RTPU 1 sends, computes the force that steers
 * the plant to its set point (PD control) and answers on loop.reply, in
 * the sensor's local memory. See loop.h. */
#include <chimera/chimera.h>
#include <chimera/bp.h>
#include <chimera/msgq.h>
#include <errno.h>
#include <stdio.h>
#include <string.h>

#include "loop.h"

static chm_msgq_t *g_sense, *g_reply;
static uint64_t g_samples, g_answers, g_unanswered;
static volatile int g_done; /* the task saw loop.sense go: its counts are final */

static void controller(void *arg) {
    (void)arg;
    for (;;) {
        loop_sample_t s;
        const int n = chm_msgq_receive(g_sense, &s, sizeof s, NULL);
        if (n == -EIDRM) { /* the queue went: the RTPU is stopping */
            g_done = 1;
            return;
        }
        if (n != (int)sizeof s) continue;
        const uint64_t now = chm_time_now();
        ++g_samples;
        const loop_reply_t r = {s.seq, s.sent_ns, now,
                                400.0 * (loop_setpoint(s.seq) - s.position) - 40.0 * s.velocity};
        if (!g_reply && chm_msgq_open(LOOP_REPLY, &g_reply) != 0) g_reply = NULL;
        if (g_reply && chm_msgq_try_send(g_reply, 1, 0, &r, sizeof r) == 0)
            ++g_answers;
        else
            ++g_unanswered;
    }
}

static void on_shutdown(void *arg) {
    (void)arg;
    /* First the queue goes, then the task ends (a sample it holds is
     * answered first), then the counts are final (bounded wait). */
    (void)!chm_msgq_destroy(LOOP_SENSE);
    for (int i = 0; i < 20 && !g_done; ++i) chm_task_pause_until(chm_time_now() + 1000000);
    printf("controller: shutdown hook: %llu samples received, %llu answered, %llu could not be answered\n",
           (unsigned long long)g_samples, (unsigned long long)g_answers, (unsigned long long)g_unanswered);
}

int main(int argc, char **argv) {
    (void)argc;
    (void)argv;
    if (loop_queue("controller", LOOP_SENSE, sizeof(loop_sample_t), 16, chm_bp_self(), &g_sense)) return 1;
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = "controller";
    a.priority = 10;
    a.critical = 1;
    chm_tid_t tid;
    const int r = chm_task_spawn(&tid, controller, NULL, &a);
    if (r) {
        printf("controller: cannot spawn: %s\n", strerror(-r));
        return 1;
    }
    if (chm_kernel_on_shutdown(on_shutdown, NULL) != 0) {
        printf("controller: %s\n", chm_err_last());
        return 1;
    }
    printf("controller: answering %s on RTPU %d (task %lld)\n", LOOP_SENSE, chm_bp_self(), (long long)tid);
    return 0;
}
