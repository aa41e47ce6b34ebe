/* Chimera host procedure calls: what a task asks of the host workstation
 * (Chimera II's "host procedure calls"), served by the host server in
 * backplane slot 0 (chimera-rtpu --host-server ROOT; `chimera start`
 * starts it) through express mail. Each call parks only the calling task.
 *
 * Errors every call may return are those listed in chimera/xfs.h (the
 * transport: -ENOTCONN, -EHOSTDOWN, -ETIMEDOUT, -EBUSY, -EPERM); after an
 * error chm_err_last() says what failed. */
#ifndef CHIMERA_HOST_H
#define CHIMERA_HOST_H

#include "chimera/status.h"

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define CHM_HOST_TIMEOUT_DEFAULT_NS 30000000000ull /* 30 s */

/* How long a file call or chm_host_getenv waits for the host server's
 * reply (0: the default). chm_host_run waits for its program however long
 * it runs; a host server that dies is seen within ~20 ms either way.
 * Process-wide. */
void chm_host_timeout_set(uint64_t timeout_ns);
uint64_t chm_host_timeout(void);

/* Change this process's working directory on the host (shared by its
 * tasks) to `path`, beneath the host server's root; "" or "." stays, ".."
 * goes up but never above the root. Errors: -EINVAL NULL; -EXDEV it leads
 * out of the root; -ENOTDIR; the host's errors (-ENOENT, -EACCES). */
CHM_CHECK int chm_host_chdir(const char* path);

/* This process's working directory, relative to the host server's root
 * ("" at the root), into buf. Errors: -EINVAL buf NULL or len 0;
 * -ERANGE it does not fit. */
CHM_CHECK int chm_host_getcwd(char* buf, size_t len);

/* The host server's environment variable `name` into buf (NUL-terminated).
 * Returns its length. Errors: -EINVAL bad name (empty, '='); -ENOENT not
 * set; -ERANGE it does not fit in `len` bytes. */
CHM_CHECK int chm_host_getenv(const char* name, char* buf, size_t len);

/* Run the host program argv[0] (searched in the host server's PATH) with
 * arguments argv[1..argc-1], in this process's host working directory,
 * with the host server's terminal as its stdin, stdout and stderr, and
 * park the calling task until it exits. Never through a shell: a shell
 * runs only when argv[0] is one (and the host server was started with
 * --host-allow-shell). *status (may be NULL) receives its exit status
 * (0..255), or 128 + the signal that killed it.
 * Errors: -EINVAL argc < 1 or argv NULL; -E2BIG the vector does not fit
 * one request; -EPERM argv[0] is a shell and shells are not allowed;
 * -ENOENT no such program; -EACCES not executable. */
CHM_CHECK int chm_host_run(int argc, const char* const* argv, int* status);

#ifdef __cplusplus
}
#endif
#endif
