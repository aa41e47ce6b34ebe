/* Chimera remote semaphores: binary and counting semaphores in backplane
 * memory, shared by tasks on every RTPU and by host processes.
 *
 * P blocks only the calling task (its RTPU keeps running its other tasks);
 * on a host thread it sleeps on a futex. V hands the semaphore to the most
 * urgent waiter (highest task priority, then first come) wherever it is,
 * through that RTPU's mailbox interrupt: a futex wake when the RTPU idles,
 * a directed signal when it runs, nothing at all while it polls its
 * mailbox before sleeping. A waiter whose process dies is removed (by the
 * backplane's recovery), and a V already handed to it is passed on.
 *
 * Every call returns 0 or a negative errno-style status; chm_bp_last_error()
 * says what was wrong in words.
 *
 * Errors under global handling (chimera/err.h): the statuses meaning a bug
 * or a missing resource (-EINVAL, -ENOENT, -ENOTCONN, -ECHRNG, -EEXIST,
 * -ENAMETOOLONG, -ENOMEM, -ENOSPC, -EMSGSIZE, -EPERM, -EBADMSG,
 * -ENOTRECOVERABLE...) are raised as error signals of module "ipc"
 * (chm_ipc_err_module, chimera/bp.h) when a task with global handling on
 * gets them; outcomes (-EAGAIN, -ETIMEDOUT, -EINTR, -EOWNERDEAD, -EIDRM,
 * -EOVERFLOW) are only returned. */
#ifndef CHIMERA_RSEM_H
#define CHIMERA_RSEM_H

#include "chimera/status.h"

#include <stdint.h>

#include "chimera/sem.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct chm_rsem chm_rsem_t; /* a handle: valid in this process */

#define CHM_RSEM_WAITERS 64 /* tasks and threads blocked on one semaphore */

/* Create the semaphore `name` (up to CHM_BP_NAME_MAX chars) of `kind` with
 * `initial` count (binary: 0 or 1), in common memory (where =
 * CHM_SHM_COMMON, -1) or in RTPU `where`'s local memory. A semaphore
 * takes about 6 KiB there: each waiter's grant word has a cache line of
 * its own, so a V to a polling waiter moves only the line it spins on.
 * Errors: -ENOTCONN not attached to a backplane; -EINVAL NULL name/out,
 * bad kind, binary initial > 1; -EEXIST name taken; -ENOMEM no room;
 * -ENOSPC registry full; -ENAMETOOLONG; -ECHRNG bad `where`; -EBADMSG that
 * memory's block chain is corrupt (chm_bp_last_error names the field). */
CHM_CHECK int chm_rsem_create(const char* name, enum chm_sem_kind kind, uint32_t initial, int where,
                    chm_rsem_t** out);

/* Open the semaphore `name` created by any process.
 * The semaphore is validated first (its registry entry, kind, count,
 * record states and waiting count).
 * Errors: -ENOTCONN; -EINVAL; -ENOENT no such semaphore; -EBADMSG it is
 * corrupt (chm_bp_last_error names the semaphore and the field). */
CHM_CHECK int chm_rsem_open(const char* name, chm_rsem_t** out);

/* P: take the semaphore, waiting as long as needed (chm_rsem_p), at most
 * `timeout_ns` (chm_rsem_p_timed), until the absolute time `deadline_ns`
 * (chm_rsem_p_until), or not at all (chm_rsem_try_p).
 * Timeouts (chimera/kernel.h): timeout_ns is relative, CHM_NO_WAIT does not
 * wait (as try_p), CHM_FOREVER waits as long as chm_rsem_p. Compatibility:
 * timeout_ns was int64_t with any negative value meaning no limit; a -1
 * passed now converts to UINT64_MAX, CHM_FOREVER, and still means no
 * limit (other negative values become huge timeouts). deadline_ns is a
 * chm_time_now() value: a task waits on its RTPU's kernel clock (exact on
 * the virtual clock), a host thread on CLOCK_MONOTONIC (chm_time_now()'s
 * clock there). A deadline already reached does not wait (a free unit is
 * still taken); CHM_FOREVER: no limit.
 * Errors: -EAGAIN not available and not waiting (try_p, or CHM_NO_WAIT);
 * -ETIMEDOUT still not available when the timeout ran out or the deadline
 * came (a past deadline included); -EINTR a user signal interrupted the
 * wait; -ENOSPC CHM_RSEM_WAITERS are waiting already; -EINVAL not a
 * semaphore handle; -ENOTRECOVERABLE damaged by a process that died in
 * it; -EDEADLK its lock was held past 5 s by a live process.
 * chm_rsem_try_p (and CHM_NO_WAIT) never waits for another process: its
 * -EAGAIN also means the semaphore's lock is held by a live process that
 * stalled inside a call (stopped, descheduled); it spins at most 20 µs for
 * the lock and chm_err_last names the holder's slot and task. A timed P
 * (or one with a deadline) waits for that lock no longer than its own
 * limit: -ETIMEDOUT then; chm_rsem_p waits up to 5 s (-EDEADLK). */
CHM_CHECK int chm_rsem_p(chm_rsem_t* sem);
CHM_CHECK int chm_rsem_p_timed(chm_rsem_t* sem, uint64_t timeout_ns);
CHM_CHECK int chm_rsem_p_until(chm_rsem_t* sem, uint64_t deadline_ns);
CHM_CHECK int chm_rsem_try_p(chm_rsem_t* sem);

/* V: wake the most urgent waiter, or count up (a binary semaphore stays
 * at 1). Never blocks on the count; waits at most 10 ms for the
 * semaphore's lock when a live process holds it. Errors: -EOVERFLOW count
 * at UINT32_MAX; -EINVAL; -ENOTRECOVERABLE; -EBUSY the lock was held by a
 * live process for 10 ms (chm_err_last names its slot and task): the unit
 * was not given, call again. */
CHM_CHECK int chm_rsem_v(chm_rsem_t* sem);

/* The count now (>= 0), or -EINVAL. */
CHM_CHECK int chm_rsem_value(chm_rsem_t* sem);
/* Number of tasks and threads waiting now, or -EINVAL. */
CHM_CHECK int chm_rsem_waiting(chm_rsem_t* sem);

/* Forget this process's handle (the semaphore lives on). Errors: -EINVAL
 * not an open remote semaphore; -ENOTCONN not attached; the registry's
 * lock errors, as chm_rsem_open's. */
CHM_CHECK int chm_rsem_close(chm_rsem_t* sem);
/* Remove the name; the memory goes when no process has it open.
 * Errors: -ENOTCONN; -EINVAL; -ENOENT. */
CHM_CHECK int chm_rsem_destroy(const char* name);

#ifdef __cplusplus
}
#endif
#endif
