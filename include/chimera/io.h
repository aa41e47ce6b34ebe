/* Chimera blocking I/O: a task that waits for the outside world parks only
 * itself, never its RTPU.
 *
 * libchimera interposes the blocking UNIX calls a control program makes
 * directly: sleep, usleep, nanosleep, clock_nanosleep, read, write, readv,
 * writev, recv, recvfrom, send, sendto, accept, accept4 and poll. Called
 * from a task on a descriptor that is not ready (a pipe, socket or
 * terminal in blocking mode), the call parks the task; the RTPU runs its
 * other tasks, its idle loop waits on the descriptor, and while other tasks
 * keep the CPU busy the descriptor is polled every io_poll_ns (see
 * chm_kernel_config). Sleeps become chm_task_pause_until on the kernel's
 * clock. Outside a task (before chm_kernel_run, on another thread, or in a
 * task locked into the CPU with chm_task_lock) the calls behave exactly as
 * in libc.
 *
 * Limits: calls libc makes internally (stdio's own writes, for instance)
 * are not interposed; printf to a terminal that stops reading blocks the
 * RTPU as before. A descriptor already in O_NONBLOCK mode is passed through
 * (the caller asked for EAGAIN). Another process that consumes a
 * descriptor's readiness between the poll and the call can make the call
 * block the RTPU. Writes larger than PIPE_BUF to a pipe, socket or terminal
 * are written in PIPE_BUF pieces, parking between them. */
#ifndef CHIMERA_IO_H
#define CHIMERA_IO_H

#include "chimera/status.h"

#include <stdint.h>

#include "chimera/kernel.h" /* CHM_FOREVER, CHM_NO_WAIT */

#ifdef __cplusplus
extern "C" {
#endif

struct pollfd;

/* poll(2) that parks only the calling task: wait until one of `fds` is
 * ready, or `timeout_ns` passes (relative, chimera/kernel.h "Timeouts":
 * CHM_NO_WAIT just looks, CHM_FOREVER no limit). Compatibility: the
 * parameter was int64_t with -1 for no limit; a -1 passed now converts to
 * UINT64_MAX, CHM_FOREVER, and still means no limit. Returns the number
 * of ready descriptors (revents filled in), 0 when none became ready in
 * time (CHM_NO_WAIT included: poll's convention, not an error).
 * Task context; elsewhere it is an ordinary poll(2).
 * Errors: -EINTR a user signal interrupted the wait; -EINVAL more than 1024
 * descriptors; -EFAULT fds NULL with nfds > 0; poll's own errors negated. */
CHM_CHECK int chm_io_poll(struct pollfd* fds, unsigned long nfds, uint64_t timeout_ns);

#ifdef __cplusplus
}
#endif
#endif
