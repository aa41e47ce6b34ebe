/* Chimera user signals between tasks of one RTPU. The target's handler runs
 * in the target's own context the next time it runs; a blocking wait it is
 * in returns -EINTR. Signals 1..31; pending signals of the same number
 * coalesce (like UNIX). */
#ifndef CHIMERA_USIG_H
#define CHIMERA_USIG_H

#include "chimera/status.h"

#include "chimera/task.h"

#ifdef __cplusplus
extern "C" {
#endif

#define CHM_USIG_MAX 31

typedef void (*chm_usig_handler_t)(int signo, void* arg);

/* Install the calling task's handler for `signo` (NULL ignores it).
 * Errors: -EINVAL signo outside 1..31; -EPERM outside a task. */
CHM_CHECK int chm_usig_handle(int signo, chm_usig_handler_t handler, void* arg);

/* Send `signo` to a task. Errors: -ESRCH, -EINVAL. Task or interrupt context. */
CHM_CHECK int chm_usig_send(chm_tid_t task, int signo);

/* Block (1) or unblock (0) delivery of signals in the mask (bit n = signo n)
 * for the calling task; returns the previous mask. */
uint32_t chm_usig_mask(uint32_t mask, int block);

#ifdef __cplusplus
}
#endif
#endif
