/* Chimera spin-locks: a lock word in shared memory (a backplane segment,
 * chimera/shm.h) that tasks on any RTPU and threads of host processes
 * take with one atomic test-and-set (a compare-and-swap that also records
 * the holder). A waiter polls at an interval the caller chooses and gives
 * the CPU away between polls (to the other tasks of its RTPU when it is a
 * Chimera task), and gives up after a bounded time.
 *
 * Robust: the lock records its holder's RTPU slot, that slot's generation
 * and the task, never a bare pid. If the holder's process dies, the next
 * locker takes the lock over and is told so (-EOWNERDEAD), so it can
 * repair what the lock protects.
 *
 * The caller's process must be attached to a backplane (chimera/bp.h).
 *
 * Errors under global handling (chimera/err.h): -EINVAL, -ENOTCONN and
 * -EPERM (unlocking a lock this caller does not hold) are raised as error
 * signals of module "ipc" (chm_ipc_err_module, chimera/bp.h) when a task
 * with global handling on gets them; the outcomes -ETIMEDOUT, -EAGAIN,
 * -EBUSY and -EOWNERDEAD are only returned. */
#ifndef CHIMERA_SPIN_H
#define CHIMERA_SPIN_H

#include "chimera/status.h"

#include <stdint.h>

#include "chimera/kernel.h" /* CHM_FOREVER, CHM_NO_WAIT */

#ifdef __cplusplus
extern "C" {
#endif

/* The lock's alignment on every target. m68k's ABI aligns a uint32_t to 2
 * bytes only, so without it a chm_spin_t on the stack or in a struct could
 * land on an address the lock's atomic word refuses (-EINVAL). */
#if defined(__GNUC__) || defined(__clang__)
#define CHM_SPIN_ALIGNED __attribute__((aligned(4)))
#else
#define CHM_SPIN_ALIGNED
#endif

/* Lives in shared memory; 16 bytes, 4-byte aligned (also on m68k, where the
 * type says so: CHM_SPIN_ALIGNED). Initialise with chm_spin_init before
 * first use; never copy a lock that may be held. */
typedef struct CHM_SPIN_ALIGNED chm_spin {
    uint32_t word;        /* holder's token: 0 = free */
    uint32_t owner_task;  /* holder's task id in 31 bits (its slot, bits 0..15, and its
                           * generation folded into 1..0x7fff), or 0x80000000 | thread id */
    uint32_t dirty;       /* free for the user: e.g. 1 while changing the data */
    uint32_t reserved;
} chm_spin_t;

/* The old name of CHM_FOREVER (chimera/kernel.h), kept for existing code. */
#define CHM_SPIN_FOREVER CHM_FOREVER

/* Make `lock` free. Errors: -EINVAL NULL or misaligned. */
CHM_CHECK int chm_spin_init(chm_spin_t* lock);

/* Acquire `lock`. For the first poll_interval_ns the waiter tests the lock
 * continuously; after that it tests once every poll_interval_ns and gives
 * the CPU away in between (poll_interval_ns 0 means 10 µs). timeout_ns
 * bounds the whole wait, relative (chimera/kernel.h "Timeouts"; measured on
 * CLOCK_MONOTONIC, also under a virtual-clock kernel): CHM_FOREVER (or
 * CHM_SPIN_FOREVER) no bound; CHM_NO_WAIT one attempt.
 * Returns 0; -EOWNERDEAD: acquired, but the previous holder died holding
 * it, or its task ended holding it (repair the data it protects); -EAGAIN: held by another, and
 * timeout_ns is CHM_NO_WAIT (it was -ETIMEDOUT before the timeout
 * convention); -ETIMEDOUT: not acquired within a positive timeout_ns;
 * -EINVAL NULL or misaligned; -ENOTCONN not attached.
 * Not recursive: a second lock by the same RTPU waits like anyone else.
 * With the interrupt mask held (an interrupt handler, a chm_irq_lock
 * section) the wait is at most 20 µs, spinning, whatever timeout_ns says:
 * nothing else of the RTPU runs meanwhile (-ETIMEDOUT then). */
CHM_CHECK int chm_spin_lock(chm_spin_t* lock, uint64_t poll_interval_ns, uint64_t timeout_ns);

/* One attempt, never waiting: 0 acquired; -EOWNERDEAD acquired from a dead
 * holder; -EAGAIN held by another. Errors: -EINVAL NULL or misaligned;
 * -ENOTCONN not attached. */
CHM_CHECK int chm_spin_try_lock(chm_spin_t* lock);

/* The name before API 1.0, kept for one release (CHANGELOG.md): as
 * chm_spin_try_lock, but a held lock gives -EBUSY. */
CHM_CHECK int chm_spin_trylock(chm_spin_t* lock);

/* Release. Errors: -EPERM not held by this RTPU (or host process);
 * -EINVAL NULL; -ENOTCONN. */
CHM_CHECK int chm_spin_unlock(chm_spin_t* lock);

#ifdef __cplusplus
}
#endif
#endif
