/* Chimera tasks: spawn, destroy, suspend, resume, priorities, periodic
 * timing, deadline failures, status, CPU lock. */
#ifndef CHIMERA_TASK_H
#define CHIMERA_TASK_H

#include "chimera/status.h"

#include <stddef.h>
#include <stdint.h>

#include "chimera/kernel.h"

#ifdef __cplusplus
extern "C" {
#endif

/* A task id: never names another task once its task has ended. 64 bits:
 * the task's slot in bits 0..15 and the slot's generation in bits 16..62,
 * so every id is positive. A slot whose 2^47 - 1 generations are used is
 * retired rather than reused, so no id repeats within a process: at the
 * fastest spawn rate (one spawn and end per ~145 ns, all on one slot) a
 * slot lasts ~236 days and the 32,768 slots ~21,000 years. Print with
 * "%lld" and a (long long) cast. (Before 1.0 it was 32 bits and repeated
 * after 32,767 spawns of one slot.) */
typedef int64_t chm_tid_t;
#define CHM_TID_NONE ((chm_tid_t)-1)
#define CHM_TASK_NAME_MAX 31

/* What a deadline-failure handler decides. */
enum chm_deadline_action {
    CHM_DL_CONTINUE = 0,     /* let the late cycle run on */
    CHM_DL_ABORT_CYCLE = 1,  /* drop this cycle; the entry restarts at the next release */
    CHM_DL_STOP_RTPU = 2     /* chm_kernel_stop(): shutdown hooks, then stop */
};

/* Facts handed to a deadline-failure handler. The handler runs once for
 * every run of misses that pass before it can run (the task was preempted
 * or is running late through several deadlines): `cycle` and
 * `deadline_ns` are the latest miss, `unhandled` says how many deadlines
 * passed since the handler last ran (>= 1), `misses` the task's total. */
typedef struct chm_deadline_info {
    chm_tid_t task;
    uint64_t cycle;          /* the cycle that missed last (0-based) */
    uint64_t deadline_ns;    /* its absolute deadline */
    uint64_t now_ns;         /* when the handler runs */
    uint64_t misses;         /* misses so far, this one included */
    uint64_t unhandled;      /* misses this call handles (since the last call) */
} chm_deadline_info_t;

/* Runs in the failing task's context (at handler_priority if set). To
 * "signal another task" call chm_usig_send() and return a decision. */
typedef enum chm_deadline_action (*chm_deadline_handler_t)(const chm_deadline_info_t* info, void* arg);

typedef struct chm_task_attr {
    const char* name;      /* copied; up to CHM_TASK_NAME_MAX chars; NULL = "task" */
    size_t stack_size;     /* 0 = kernel default; minimum 8 KiB */
    int priority;          /* static user priority: higher runs first among equals */
    int critical;          /* MUF: 1 = always in the critical set */
    uint64_t period_ns;    /* 0 = aperiodic */
    uint64_t deadline_ns;  /* relative deadline; 0 = the period; must be <= period */
    uint64_t wcet_ns;      /* estimated worst-case CPU time per cycle (MLF, MUF) */
    uint64_t start_ns;     /* absolute first release; 0 = now */
    chm_deadline_handler_t on_deadline; /* NULL: the miss becomes an error signal */
    void* on_deadline_arg;
    int handler_priority;  /* 0 = run the handler at the task's own priority */
    int joinable;          /* 1: keep its slot and final status until chm_task_join */
} chm_task_attr_t;

/* Fill `attr` with defaults (aperiodic, priority 0, default stack). */
void chm_task_attr_init(chm_task_attr_t* attr);

/* Create a task running entry(arg); it becomes ready at once (periodic:
 * at start_ns). May be called before chm_kernel_run (after init) and from
 * tasks. Errors: -EINVAL NULL entry, stack below 8 KiB, deadline longer than
 * the period, wcet longer than the deadline, period without a positive
 * deadline; -ENAMETOOLONG; -EAGAIN the scheduler refused admission or
 * all 32,768 task slots are in use (or retired: see chm_tid_t); -ENOMEM; -EPERM kernel not initialised. Nothing is left behind on error. */
CHM_CHECK int chm_task_spawn(chm_tid_t* out, void (*entry)(void* arg), void* arg, const chm_task_attr_t* attr);

/* End the calling task (exit status 0). Task context. Does not return.
 * Its end hooks run first (chm_task_on_end). */
void chm_task_exit(void);

/* End the calling task with `status`, which chm_task_join reports. Task
 * context. Does not return. */
void chm_task_end(int status);

/* Destroy a task (itself included: then like chm_task_exit). It is taken
 * off the CPU first, then its end hooks run in the caller's context, then
 * its stack is freed; semaphores it holds are NOT released (see chm_sem
 * docs). A task inside a backplane call (queue, remote semaphore, shared
 * memory, express mail) is not ended there: its wait is cancelled and it
 * ends when the call returns, so 0 may come back before it has ended
 * (chm_task_join waits for that); whatever backplane locks and records a
 * task holds are given back however it ends. Errors: -ESRCH unknown task. */
CHM_CHECK int chm_task_destroy(chm_tid_t task);

/* How a task ended (chm_task_status_t.end_reason). */
enum chm_task_end_reason {
    CHM_TASK_LIVE = 0,      /* it has not ended */
    CHM_TASK_RETURNED = 1,  /* its entry returned (exit status 0) */
    CHM_TASK_EXITED = 2,    /* chm_task_exit or chm_task_end(status) */
    CHM_TASK_ABORTED = 3,   /* an error signal or processor exception aborted it */
    CHM_TASK_DESTROYED = 4  /* chm_task_destroy by another task, or the RTPU's end */
};

/* Run hook(arg) when the calling task ends, whichever way: return, exit,
 * abort, destroy, the kernel's teardown (chm_kernel_fini). Hooks run most
 * recently registered first, once each, before the task's end is visible
 * to joiners. They run in the task's own context when it ends itself
 * (return, exit, abort), and in the destroyer's context (or the kernel
 * thread's, at teardown) when another ends it; a hook that faults or raises
 * an error does not stop the others. Up to 8 per task. Task context.
 * Errors: -EINVAL NULL hook; -ENOSPC 8 already; -EPERM not in a task;
 * -ENOMEM. */
CHM_CHECK int chm_task_on_end(void (*hook)(void* arg), void* arg);

/* Task-local storage: a key names one slot in every task; a task's value
 * for it starts NULL. Up to 32 keys per RTPU; keys are never deleted.
 * `destructor` (may be NULL) is called with a task's non-NULL value when
 * that task ends, after its end hooks. Errors: -EINVAL NULL key; -EAGAIN
 * 32 keys exist. */
typedef uint32_t chm_task_key_t;
CHM_CHECK int chm_task_key_create(chm_task_key_t* key, void (*destructor)(void* value));
/* The calling task's value for `key` (NULL if none, or outside a task). */
void* chm_task_get_local(chm_task_key_t key);
/* Set it. Errors: -EINVAL unknown key; -EPERM not in a task; -ENOMEM. */
CHM_CHECK int chm_task_set_local(chm_task_key_t key, void* value);

/* Timing of a periodic task, as chm_task_set_timing takes it. */
typedef struct chm_task_timing {
    uint64_t period_ns;    /* > 0 */
    uint64_t deadline_ns;  /* relative; 0 = the period; <= period */
    uint64_t wcet_ns;      /* estimated CPU per cycle; <= deadline */
    int critical;          /* MUF: 1 = always in the critical set */
} chm_task_timing_t;

/* Change a periodic task's timing while it runs. Takes effect at its next
 * release: that cycle has the new deadline and estimate, and releases from
 * it on are spaced by the new period (the next release itself stays where
 * the old period put it: the grid is never broken). The scheduler re-admits
 * the task then (MUF's critical set is updated; among tasks of equal period
 * it ranks as the newest). A later call before that release replaces an
 * earlier one. A task that holds a semaphore while a more urgent waiter
 * lends it its timing takes the change at its first release after the
 * loan. Under a user scheduler that refuses the new timing at that
 * release, the task keeps its old timing and the refusal is counted in
 * chm_task_status_t.timing_refused.
 * Errors: -ESRCH unknown task; -EINVAL NULL, an aperiodic task (period 0),
 * a period of 0, a deadline beyond the period, an estimate beyond the
 * deadline. */
CHM_CHECK int chm_task_set_timing(chm_tid_t task, const chm_task_timing_t* timing);

/* Suspend until chm_task_resume (counted). Errors: -ESRCH. */
CHM_CHECK int chm_task_suspend(chm_tid_t task);
/* Errors: -ESRCH; -EINVAL not suspended. */
CHM_CHECK int chm_task_resume(chm_tid_t task);

/* Change the static user priority (re-sorts it wherever it waits).
 * Errors: -ESRCH. */
CHM_CHECK int chm_task_set_priority(chm_tid_t task, int priority);

/* The calling task, or CHM_TID_NONE outside a task. Any context. */
chm_tid_t chm_task_self(void);

/* Find a task by name. Errors: -ESRCH none; -EINVAL NULL. */
CHM_CHECK int chm_task_find(const char* name, chm_tid_t* out);

/* Give the CPU to the next ready task of equal urgency, if any. Task context. */
void chm_task_yield(void);

/* Pause until the absolute time restart_ns (the paper's pause(restart_time)).
 * Returns 0, or -EINTR when a user signal interrupted the pause. */
int chm_task_pause_until(uint64_t restart_ns);

/* Periodic tasks: end this cycle and wait for the next release (absolute
 * release times: no drift). Returns 0, -EINTR (user signal), or -EINVAL for
 * an aperiodic task. */
int chm_task_wait_period(void);

/* Release time of the calling periodic task's current cycle (absolute, on
 * the grid), or 0 outside a periodic task. Release lateness is
 * chm_time_now() - chm_task_cycle_release() at the start of a cycle. */
uint64_t chm_task_cycle_release(void);

/* Lock the calling task into the CPU (no preemption; timers still counted)
 * and unlock; nestable. Blocking while locked unlocks for the wait. */
void chm_task_lock(void);
void chm_task_unlock(void);

enum chm_task_state {
    CHM_TASK_READY, CHM_TASK_RUNNING, CHM_TASK_BLOCKED, CHM_TASK_SUSPENDED,
    CHM_TASK_WAITING_PERIOD, CHM_TASK_PAUSED, CHM_TASK_ENDED
};

typedef struct chm_task_status {
    chm_tid_t id;
    char name[CHM_TASK_NAME_MAX + 1];
    enum chm_task_state state;
    int priority;             /* static user priority */
    int critical;             /* in the MUF critical set */
    uint64_t period_ns, deadline_ns, wcet_ns;
    uint64_t cpu_ns;          /* CPU time consumed in all */
    uint64_t cycles;          /* cycles completed */
    uint64_t misses;          /* deadline misses */
    uint64_t worst_lateness_ns;   /* worst completion after the deadline */
    uint64_t worst_cycle_cpu_ns;  /* worst CPU time of one cycle */
    size_t stack_size;
    size_t stack_high_water;  /* most stack ever used, bytes */
    enum chm_task_end_reason end_reason; /* CHM_TASK_LIVE while it runs */
    int exit_status;          /* chm_task_end's status; 0 otherwise */
    uint64_t timing_refused;  /* chm_task_set_timing changes a user scheduler refused */
} chm_task_status_t;

/* Snapshot of a task. A task that ended stays readable (state
 * CHM_TASK_ENDED, its final counters; stack_high_water as measured when its
 * stack was released) until its slot is taken by a new task. Of the free
 * slots, in the order they were freed, a spawn takes the 65th most recently
 * freed when more than 64 are free, else the least recently freed: a slot
 * is not taken while 64 slots freed after it are free, nor before every
 * slot freed before it. (Tasks spawned and ended in turn thus reuse a few
 * TCBs, kept in the cache, even after a burst of thousands of tasks.) A
 * joinable task's status is kept until chm_task_join.
 * Errors: -ESRCH unknown task (or ended and its slot reused), -EINVAL NULL. */
CHM_CHECK int chm_task_status(chm_tid_t task, chm_task_status_t* out);

/* Wait until `task` ends (at most timeout_ns, relative, chimera/kernel.h
 * "Timeouts": CHM_NO_WAIT only looks, CHM_FOREVER waits as long as it
 * takes), then give its final status (out may be NULL: end_reason and
 * exit_status say how it ended) and free its slot: its id is stale from
 * then on. Only a task spawned with attr.joinable can be joined, by one
 * task at a time; it keeps its slot until then. Task context.
 * Errors: -ESRCH unknown task; -EINVAL not joinable; -EDEADLK joining
 * itself; -EBUSY another task joins it; -EAGAIN it has not ended and
 * timeout_ns is CHM_NO_WAIT; -ETIMEDOUT it did not end within timeout_ns
 * (either way it stays joinable); -EINTR a user signal interrupted the
 * wait; -EPERM not in a task. */
CHM_CHECK int chm_task_join(chm_tid_t task, uint64_t timeout_ns, chm_task_status_t* out);

/* Returns the number of tasks alive. Never fails. Any context. */
int chm_task_count(void);

#ifdef __cplusplus
}
#endif
#endif
