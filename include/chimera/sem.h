/* Chimera local semaphores (tasks of one RTPU), binary and counting.
 * Waiters queue by scheduling urgency (then arrival). A binary semaphore
 * created with CHM_SEM_INHERIT lends its holder the urgency of its most
 * urgent waiter (priority inheritance) while it is held. */
#ifndef CHIMERA_SEM_H
#define CHIMERA_SEM_H

#include "chimera/status.h"

#include <stdint.h>

#include "chimera/kernel.h" /* CHM_FOREVER, CHM_NO_WAIT */

#ifdef __cplusplus
extern "C" {
#endif

enum chm_sem_kind { CHM_SEM_BINARY = 0, CHM_SEM_COUNTING = 1 };
#define CHM_SEM_INHERIT 0x1u     /* binary only: priority inheritance */
#define CHM_SEM_COUNT_MAX 0x7fffffffu

/* Opaque; embed it anywhere (static, in a struct, on a stack). */
typedef struct chm_sem {
    uint64_t opaque[6];
} chm_sem_t;

/* Create. Binary: initial is 0 or 1. Errors: -EINVAL bad kind, flags or
 * initial count (above 1 for binary, above CHM_SEM_COUNT_MAX). */
CHM_CHECK int chm_sem_init(chm_sem_t* sem, enum chm_sem_kind kind, uint32_t initial, uint32_t flags);

/* Destroy: waiters wake with -EIDRM. Errors: -EINVAL not a semaphore. */
CHM_CHECK int chm_sem_destroy(chm_sem_t* sem);

/* P: take one unit, blocking while none is free. Task context.
 * Returns 0, -EINTR (a user signal interrupted the wait), -EIDRM
 * (destroyed while waiting), -EINVAL. A binary semaphore whose holder was
 * aborted by an error (chimera/err.h) returns -EOWNERDEAD once, to the
 * P that takes it next: the unit IS taken (as 0), but what it guarded may
 * be inconsistent. All P variants do the same. */
CHM_CHECK int chm_sem_p(chm_sem_t* sem);

/* P waiting at most `timeout_ns` (relative, chimera/kernel.h "Timeouts"):
 * CHM_NO_WAIT takes a free unit or fails at once with -EAGAIN (as
 * chm_sem_try_p); CHM_FOREVER waits as long as chm_sem_p. Task context.
 * Errors: those of chm_sem_p; -EAGAIN none free and CHM_NO_WAIT;
 * -ETIMEDOUT none came within timeout_ns; -EPERM not a task (only when
 * it would have to wait). */
CHM_CHECK int chm_sem_p_timed(chm_sem_t* sem, uint64_t timeout_ns);

/* P waiting until the absolute time `deadline_ns` (a chm_time_now()
 * value, on the kernel's clock; exact on the virtual clock), for loops
 * that wait against a fixed instant. A deadline already reached does not
 * wait: a free unit is taken, else -ETIMEDOUT. CHM_FOREVER: no limit.
 * Task context. Errors: those of chm_sem_p_timed, but never -EAGAIN. */
CHM_CHECK int chm_sem_p_until(chm_sem_t* sem, uint64_t deadline_ns);

/* P without blocking: 0 or -EAGAIN. Any task context. */
CHM_CHECK int chm_sem_try_p(chm_sem_t* sem);

/* V: give one unit, waking the most urgent waiter (which runs at once when
 * it is more urgent than the caller). Errors: -EOVERFLOW count at its
 * maximum (binary: already 1); -EINVAL. Task or interrupt context. */
CHM_CHECK int chm_sem_v(chm_sem_t* sem);

/* Returns the current count (0 while tasks wait). Errors: -EINVAL not an
 * initialised semaphore. Any context. */
int chm_sem_value(const chm_sem_t* sem);

#ifdef __cplusplus
}
#endif
#endif
