/* Chimera RTPUs seen from anywhere on the backplane: calls that act on
 * another RTPU through its express mail (docs/backplane.md, "RTPU
 * processes and express mail").
 *
 * Each RTPU (a chimera-rtpu process) runs a server task that serves a ring
 * of request records in the backplane. A call here writes one record into
 * the target's ring, raises the target's express-mail interrupt and waits
 * for the reply: a task parks only itself, a host thread sleeps on a futex.
 * Every call is bounded by the express-mail timeout (chm_rtpu_timeout_set,
 * default CHM_RTPU_TIMEOUT_DEFAULT_NS); a target that is absent or dies
 * gives an error, never a hang. Express mail sets things up; no data path
 * (shared memory, spin-locks, semaphores, queues) goes through it.
 *
 * Callable from any task of an RTPU or any thread of a host process
 * attached to the backplane (chimera/bp.h), not from interrupt handlers.
 *
 * Errors every call may return, besides its own:
 *   -ENOTCONN   this process is not attached to a backplane;
 *   -ECHRNG     `rtpu` is not a slot of the backplane;
 *   -EHOSTDOWN  slot `rtpu` runs no RTPU (free, dead, a host program), or
 *               the RTPU left or died before it replied;
 *   -ETIMEDOUT  the RTPU is alive but did not reply within the timeout
 *               (the request may still take effect later);
 *   -EBUSY      the RTPU's ring stayed full for the whole timeout;
 *   -EMSGSIZE   the request does not fit one ring record (the backplane's
 *               ring_record_size; chimera start creates 1 KiB records), or
 *               the records are below CHM_RTPU_RECORD_MIN bytes;
 *   -EDEADLK    a request to the caller's own RTPU from its kernel thread
 *               outside a task (its server could never run);
 *   -EPERM      called from an interrupt handler.
 * After an error chm_err_last() says what failed. */
#ifndef CHIMERA_RTPU_H
#define CHIMERA_RTPU_H

#include "chimera/status.h"

#include <stdint.h>

#include "chimera/kernel.h"
#include "chimera/task.h"

#ifdef __cplusplus
extern "C" {
#endif

#define CHM_RTPU_TIMEOUT_DEFAULT_NS 2000000000ull /* 2 s */
#define CHM_RTPU_RECORD_MIN 128 /* smallest usable ring record, bytes */

/* What an RTPU says about itself. */
typedef struct chm_rtpu_info {
    int32_t pid;                   /* its process */
    uint32_t tasks;                /* tasks alive, its server task included */
    enum chm_sched_policy policy;  /* scheduling policy in force */
    uint32_t served;               /* requests its server answered */
    uint64_t uptime_ns;            /* since its server started */
} chm_rtpu_info_t;

/* One task of an RTPU, as chm_rtpu_tasks lists it: the figures of
 * chm_task_status (chimera/task.h) on that RTPU, read when its server
 * served the page. */
typedef struct chm_rtpu_task {
    chm_tid_t id;
    char name[CHM_TASK_NAME_MAX + 1];
    enum chm_task_state state;
    int priority;
    int critical;            /* in the MUF critical set */
    uint64_t period_ns;      /* 0: aperiodic */
    uint64_t cpu_ns;         /* CPU time consumed */
    uint64_t cycles;         /* cycles completed */
    uint64_t misses;         /* deadline misses */
    uint64_t deadline_ns;    /* relative deadline (periodic tasks; 0 otherwise) */
    uint64_t wcet_ns;        /* declared CPU estimate per cycle (0: none) */
    uint64_t worst_lateness_ns;  /* worst completion after its deadline (0: never late) */
    uint64_t worst_cycle_cpu_ns; /* most CPU time one cycle took */
    uint64_t stack_size;         /* bytes */
    uint64_t stack_high_water;   /* most stack it ever used, bytes: from its top
                                  * down to the deepest byte ever written */
} chm_rtpu_task_t;

/* Set the time every later call of this process waits for a reply
 * (0: the default), kept in µs (at least 1 µs, at most 71 minutes). Any
 * thread. */
void chm_rtpu_timeout_set(uint64_t timeout_ns);
/* The timeout in force, ns. */
uint64_t chm_rtpu_timeout(void);

/* Ask RTPU `rtpu` whether it serves, and (info may be NULL) about itself.
 * Returns 0 or an error above. */
CHM_CHECK int chm_rtpu_ping(int rtpu, chm_rtpu_info_t* info);

/* Load the control program `path` (a shared object with a main, see
 * chimera/program.h) on RTPU `rtpu` and start its main(argc, argv) as a
 * task there. argv is passed as given (argv[0] included). A relative path
 * is resolved by the target against its own working directory. *tid (may
 * be NULL) receives main's task id on that RTPU.
 * Errors: -EINVAL path NULL or empty, argc < 0, argv NULL with argc > 0;
 * and the target's chm_program_load errors, with its message ("RTPU n
 * cannot load FILE: cause") in chm_err_last: -ENOENT no such file,
 * -EACCES the target does not trust the file (the target's log names the
 * requesting slot), -ENOEXEC not a loadable shared object, one linked
 * against libchimera, or one without a main, -ENOSPC too many programs,
 * -ENOMEM, -EAGAIN admission refused. */
CHM_CHECK int chm_rtpu_spawn(int rtpu, const char* path, int argc, const char* const* argv, chm_tid_t* tid);

/* Send user signal `signo` (1..CHM_USIG_MAX) to task `task` of RTPU
 * `rtpu` (chimera/usig.h: its handler runs in its own context; a wait it
 * is in returns -EINTR). Errors: -EINVAL bad signo; -ESRCH no such task
 * there. */
CHM_CHECK int chm_rtpu_signal(int rtpu, chm_tid_t task, int signo);

/* Find the task called `name` on RTPU `rtpu`: *tid receives its id.
 * Errors: -EINVAL NULL or a name longer than CHM_TASK_NAME_MAX; -ESRCH no
 * task of that name. */
CHM_CHECK int chm_rtpu_find(int rtpu, const char* name, chm_tid_t* tid);

/* Destroy task `task` of RTPU `rtpu` (chm_task_destroy there).
 * Errors: -ESRCH no such task; -EPERM it is the RTPU's server task. */
CHM_CHECK int chm_rtpu_destroy(int rtpu, chm_tid_t task);

/* List the tasks of RTPU `rtpu`: up to `max` go into out[], in task-slot
 * order. Returns how many were filled (>= 0); *total (may be NULL) receives
 * how many tasks the RTPU has. Long lists take several requests (one ring
 * record each), all within one timeout; tasks that start or end meanwhile
 * may be missed or seen once. Errors: -EINVAL out NULL with max > 0, or
 * max < 0; -EPROTO the RTPU's entries are of another size than this
 * library's (chimera-rtpu from another Chimera version), or a malformed
 * reply. */
CHM_CHECK int chm_rtpu_tasks(int rtpu, chm_rtpu_task_t* out, int max, int* total);

/* Stop RTPU `rtpu` gracefully: it replies, then calls
 * chm_kernel_stop(code) (shutdown hooks run); a chimera-rtpu process then
 * leaves the backplane and exits. Returns 0 once the RTPU accepted. */
CHM_CHECK int chm_rtpu_stop(int rtpu, int code);

/* What the last failing chm_rtpu_* call of this thread said, or "".
 * chm_err_last() (err.h) gives the same text per task, whatever the
 * subsystem: use it; this call is kept for one release (CHANGELOG.md). */
const char* chm_rtpu_last_error(void);

#ifdef __cplusplus
}
#endif
#endif
