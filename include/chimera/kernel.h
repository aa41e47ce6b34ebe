/* Chimera kernel: start, run and stop one RTPU's kernel; time.
 *
 * Every function returns 0 (CHM_OK) or a negative errno-style status and
 * never throws. Calling-context rules: functions marked "task context" must
 * be called from a task; others say where they may be called. */
#ifndef CHIMERA_KERNEL_H
#define CHIMERA_KERNEL_H

#include "chimera/status.h"

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define CHM_OK 0

/* Timeouts, in every blocking call that takes one (docs/architecture.md,
 * "Timeouts"): uint64_t relative nanoseconds with these two named values,
 * or, in the _until calls, an absolute chm_time_now() deadline (CHM_FOREVER:
 * none; one already past: do not wait). -EAGAIN: CHM_NO_WAIT could not
 * succeed at once; -ETIMEDOUT: a positive timeout ran out, or the deadline
 * came. */
#define CHM_FOREVER UINT64_MAX /* wait as long as it takes */
#define CHM_NO_WAIT 0          /* do not wait: succeed now or fail */

/* Built-in scheduling policies (sched.h defines each precisely; docs/architecture.md, "One RTPU"). */
enum chm_sched_policy {
    CHM_SCHED_MUF = 0, /* maximum urgency first: criticality, laxity, priority (default) */
    CHM_SCHED_RM = 1,  /* rate monotonic: shorter period first, then priority */
    CHM_SCHED_EDF = 2, /* earliest absolute deadline first */
    CHM_SCHED_MLF = 3, /* minimum laxity first */
    CHM_SCHED_FIXED = 4, /* static user priority only */
    CHM_SCHED_USER = 5   /* the ops table given in chm_kernel_config.user_sched */
};

struct chm_sched_ops; /* see chimera/sched.h */

typedef struct chm_kernel_config {
    enum chm_sched_policy policy;        /* default CHM_SCHED_MUF */
    const struct chm_sched_ops* user_sched; /* with CHM_SCHED_USER */
    void* user_sched_arg;                /* passed to every user op */
    uint64_t quantum_ns;  /* round robin among equals; 0 = none. Default 1 ms */
    int virtual_clock;    /* 1: time advances only through chm_time_consume() */
    size_t default_stack; /* stack of tasks spawned with stack_size 0; default 64 KiB */
    int rtpu_id;          /* the RTPU number printed in diagnostics (default 1) */
    int cpu_accounting;   /* 1 (default): CPU time charged at every switch, one
                           * clock read each; 0: charged at timer ticks and
                           * cycle ends only (statistical between them), which
                           * saves the clock read on yield and semaphore
                           * hand-offs (~5 ns of a ~23 ns yield where the
                           * cycle counter serves: a constant-rate TSC under
                           * clocksource tsc or kvm-clock; ~25 ns where it
                           * does not and CLOCK_MONOTONIC is read) */
    uint64_t io_poll_ns;  /* while tasks are parked in blocking UNIX calls
                           * (read, write, sleep...; see chimera/io.h) and
                           * other tasks keep the CPU busy, their descriptors
                           * are polled this often; an idle RTPU waits on them
                           * directly. Default 1 ms; minimum 10 µs */
    uint64_t idle_poll_ns; /* with nothing to run, poll the RTPU's mailbox
                           * this long before sleeping: a wake-up from a busy
                           * peer (remote V, message) then costs no system
                           * call on either side, at the price of that much
                           * CPU per idle period. A task whose remote wait
                           * (chm_rsem_p, chm_msgq_*) must block while no
                           * other task is ready does this poll itself, on
                           * its grant, before it parks: a grant then costs
                           * no switch either. It stays preemptible; another
                           * task made ready ends the poll, a user signal
                           * interrupts the wait (-EINTR). Default 0 (sleep
                           * at once) */
    int64_t timer_lead_ns; /* an idle RTPU wakes this long ahead of its next
                           * timer event (a release, a deadline, a timeout)
                           * and polls until the event is due, so the event
                           * runs on time instead of one host wake-up
                           * latency late (tens of µs on a virtual machine);
                           * never early. Costs up to that much CPU per idle
                           * period that ends at a timer event.
                           * CHM_TIMER_LEAD_AUTO (default): learnt, the 75th
                           * percentile of the host's recent wake-up
                           * latencies, at most 200 µs (chm_kernel_timer_lead
                           * reads it); 0: off, the idle RTPU sleeps until
                           * the host timer fires; 1..1000000: that lead */
} chm_kernel_config_t;

#define CHM_TIMER_LEAD_AUTO (-1)

/* Fill `cfg` with the defaults above. */
void chm_kernel_config_init(chm_kernel_config_t* cfg);

/* Initialise the kernel on the calling thread, which becomes the kernel
 * thread (it receives the one timer signal). NULL means defaults.
 * Errors: -EBUSY already initialised; -EINVAL bad config (unknown policy,
 * CHM_SCHED_USER without a complete ops table, quantum_ns or io_poll_ns
 * below 10 µs, timer_lead_ns below -1 or above 1 ms);
 * -ENOMEM; or the error of timer creation. */
CHM_CHECK int chm_kernel_init(const chm_kernel_config_t* cfg);

/* Run the tasks spawned so far (and those they spawn) until every task has
 * ended or chm_kernel_stop() is called. Returns the stop code (0 when all
 * tasks ended). Call on the kernel thread after chm_kernel_init.
 * Errors: -EPERM not initialised or called from a task. */
CHM_CHECK int chm_kernel_run(void);

/* Stop the RTPU gracefully: shutdown hooks run (most recently registered
 * first), then chm_kernel_run returns `code`. Task context. Does not return
 * to the caller. The hooks run in the caller's context while the other
 * tasks go on running, so a hook may block briefly: pause, or wait for a
 * task to finish its cycle so that the counts it prints are final (a hook
 * that never returns holds the stop). A second call while the hooks run
 * only suspends its caller; called from a hook, it returns at once. */
void chm_kernel_stop(int code);

/* Register a hook run by chm_kernel_stop (actuators first: register them
 * last). Up to 32 hooks. Errors: -ENOSPC, -EINVAL for NULL. */
CHM_CHECK int chm_kernel_on_shutdown(void (*hook)(void* arg), void* arg);

/* Tear the kernel down after chm_kernel_run returned (tests, embedding):
 * destroys remaining tasks, frees stacks, deletes the timer. */
void chm_kernel_fini(void);

/* The policy in force (after a failed user scheduler: CHM_SCHED_MUF). */
enum chm_sched_policy chm_kernel_policy(void);

/* The lead (ns) the idle RTPU wakes ahead of a timer event now: the
 * configured timer_lead_ns, or what CHM_TIMER_LEAD_AUTO has learnt; 0 when
 * the lead is off, on the virtual clock, or before chm_kernel_init. */
uint64_t chm_kernel_timer_lead(void);

/* Monotonic time in ns (virtual time in virtual-clock mode). Any context. */
uint64_t chm_time_now(void);

/* Virtual-clock mode: the calling task consumes `ns` of CPU time; timers
 * that fall due meanwhile fire at their exact virtual time and may preempt
 * the caller, which resumes consuming the rest later. In real-clock mode it
 * busy-waits `ns` of CPU time. Task context. */
void chm_time_consume(uint64_t ns);

#ifdef __cplusplus
}
#endif
#endif
