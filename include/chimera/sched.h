/* Chimera scheduler interface: the operations table every scheduling policy
 * implements, the built-in ones (RM, EDF, MLF, MUF, fixed priority) and a
 * user scheduler installed at start-up alike. A user scheduler is called
 * only through these operations; under a built-in policy the kernel runs
 * the same operations' code directly (no indirect call per switch). A
 * built-in table installed as a user scheduler behaves like the built-in.
 *
 * All operations run with the kernel's interrupt mask held: they must not
 * block, allocate, call the C library or the Chimera API.
 *
 * The schedule, precisely (the built-in policies; a user policy is called
 * at the same decision points):
 *
 * Order. Ready tasks are ordered by the policy's key, then by user
 * priority (higher first), then first come:
 *   RM    the period (aperiodic tasks after every periodic one);
 *   EDF   the absolute deadline of the current cycle (none: last);
 *   MLF   the laxity: absolute deadline - now - remaining estimated CPU,
 *         where remaining = wcet - CPU used this cycle, at least 0;
 *   MUF   the critical set first, then the laxity. The critical set is the
 *         user-marked tasks, then the longest prefix of the other periodic
 *         tasks in rate order (period, then spawn order) whose worst-case
 *         utilisation, each wcet/period in parts per billion rounded down,
 *         keeps the total <= 1; it changes when a task is spawned or ends;
 *   FIXED the user priority only.
 * "First come" is the instant a task last became ready: a release, a
 * wake-up, a yield, the end of its quantum. A preempted task keeps its
 * place. Timers due at one instant fire in task-index order (spawn order in
 * a fresh kernel), so simultaneous releases arrive in that order.
 *
 * Decisions. The scheduler re-evaluates the keys (laxities included) and
 * picks at every release, job completion (chm_task_wait_period), block,
 * wake-up, deadline passing (deadline + 1 ns), spawn and end of a task, and
 * at every end of the running task's quantum (the paper's time-driven
 * reschedule). Quanta end at dispatch + k * quantum_ns while a task keeps
 * the CPU; with quantum_ns 0 there are none. Between decisions the running
 * task keeps the CPU, even under MLF when a waiting task's laxity falls
 * below its own. The running task gives the CPU only to a task strictly
 * before it; at the end of its quantum it also gives it to an equal one and
 * goes behind its equals (round robin). A quantum's end is armed only when
 * a decision there can change something (an equal waits; under MLF or MUF
 * a waiting task with a deadline, in MUF's same class, whose laxity may
 * fall below the running task's; under a user policy any waiting task), so
 * a task alone at its urgency takes no ticks.
 *
 * One instant. When the running task's work ends at an instant at which
 * other events fall due (a release, a deadline, a quantum's end), it runs
 * on to its next kernel call before they are acted on: a job whose work
 * ends at or before its deadline is on time, whoever is released then. (On
 * the virtual clock this is exact; on the real clock the timer signal
 * decides at the instant it lands.)
 *
 * Late cycles. A cycle that has not completed by its deadline is a miss,
 * counted at deadline + 1 ns; it runs on (or its handler decides). When a
 * late task calls chm_task_wait_period and its next release is already
 * due, that cycle starts at once as a new arrival (behind its equals) and
 * the scheduler decides who runs; releases stay on the grid
 * start + k * period, none is skipped.
 *
 * CPU time: with cpu_accounting 1 (default) the running task is charged at
 * every switch and every event, so MLF and MUF compare its laxity as of
 * now; with 0, as of the last timer tick.
 *
 * tests/kernel/test_kernel_sched_diff.cpp checks all of this against an
 * independent simulator written from this text. */
#ifndef CHIMERA_SCHED_H
#define CHIMERA_SCHED_H

#include <stdint.h>
#include "chimera/task.h"

#ifdef __cplusplus
extern "C" {
#endif

/* The scheduler's view of one task. The kernel owns and updates every field
 * but the scratch ones at the end. */
typedef struct chm_sched_task {
    chm_tid_t id;
    int priority;            /* static user priority: higher first */
    int critical;            /* user-declared critical (MUF) */
    uint64_t period_ns;      /* 0 = aperiodic */
    uint64_t deadline_ns;    /* relative deadline */
    uint64_t wcet_ns;        /* estimated CPU time per cycle */
    uint64_t release_ns;     /* release of the current cycle */
    uint64_t abs_deadline_ns;/* absolute deadline of the current cycle; UINT64_MAX aperiodic */
    uint64_t cycle_cpu_ns;   /* CPU used in the current cycle so far */
    uint64_t seq;            /* arrival order: among equals, smaller runs first */
    /* scratch, owned by the scheduler */
    int32_t slot;
    int32_t flags;
    uint64_t key;
    void* data;
} chm_sched_task_t;

typedef struct chm_sched_ops {
    const char* name;
    /* Required. A new task is known (before it is first enqueued); return 0
     * to accept it or a negative status (-EAGAIN) to refuse it. */
    int (*admit)(void* self, chm_sched_task_t* t);
    /* Required. The task is gone for good (it is not enqueued). A task
     * whose timing changes (chm_task_set_timing) is retired and admitted
     * again at its next release, with the new timing. */
    void (*retire)(void* self, chm_sched_task_t* t);
    /* Required. The task became ready (it is not the running task). */
    void (*enqueue)(void* self, chm_sched_task_t* t, uint64_t now);
    /* Required. A ready task left the ready set (it runs, blocks, ends). */
    void (*dequeue)(void* self, chm_sched_task_t* t);
    /* Required. The ready task that should run now, left in the ready set;
     * NULL when none. Returning anything else than an enqueued task is a
     * scheduler failure: the kernel falls back to MUF and reports it. */
    chm_sched_task_t* (*pick)(void* self, uint64_t now);
    /* Required. 1 when `a` must run before `b` now, else 0. Two tasks
     * neither of which runs before the other share the CPU round robin. */
    int (*before)(void* self, const chm_sched_task_t* a, const chm_sched_task_t* b, uint64_t now);
    /* Optional. A new cycle of a periodic task begins (its release and
     * absolute deadline are already updated; it is not enqueued yet). */
    void (*release)(void* self, chm_sched_task_t* t, uint64_t now);
    /* Optional. Called at every tick: refresh dynamic priorities. */
    void (*update)(void* self, uint64_t now);
} chm_sched_ops_t;

/* The built-in operations tables (the state they need is the kernel's). */
extern const chm_sched_ops_t chm_sched_muf_ops;
extern const chm_sched_ops_t chm_sched_rm_ops;
extern const chm_sched_ops_t chm_sched_edf_ops;
extern const chm_sched_ops_t chm_sched_mlf_ops;
extern const chm_sched_ops_t chm_sched_fixed_ops;

/* Returns the number of times the user scheduler failed and the kernel fell
 * back to MUF (0 or 1); the reason of the failure as text ("" when none).
 * Never fail. */
int chm_sched_fallbacks(void);
const char* chm_sched_fallback_reason(void);

#ifdef __cplusplus
}
#endif
#endif
