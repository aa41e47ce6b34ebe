/* Chimera extended file system: host files from any RTPU task, served by
 * the host server (chimera-rtpu --host-server ROOT in backplane slot 0,
 * which `chimera start` starts) through express mail.
 *
 * A call parks only the calling task: the RTPU's other tasks keep their
 * periods while the host server does the blocking work, so a task can read
 * a large host file beside a 1 kHz loop (a direct read() of a regular file
 * blocks the whole RTPU: the kernel cannot poll a disk). Data beyond what
 * one express-mail record carries moves through a transfer segment in
 * common memory ("chimera.hostio.<slot>", 4 x 256 KiB, made on first use);
 * each request moves at most 256 KiB, larger reads and writes are split.
 * Sequential reads of a regular file of at least 16 KiB are read ahead:
 * up to 3 blocks of 256 KiB in flight, the position kept by the caller
 * until another call on the handle (src/host/stream.cpp).
 *
 * Paths are relative to the calling RTPU's working directory on the host
 * (chm_host_chdir), itself beneath the root directory the host server was
 * given: absolute paths, ".." above the root and symbolic links that lead
 * out of it are refused (-EXDEV), however they are spelled.
 *
 * Callable from tasks and from threads of host processes attached to the
 * backplane. Every call returns >= 0 or a negative errno-style status, and
 * after an error chm_err_last() says what failed, naming the path or
 * handle. Errors every call may return, besides its own:
 *   -ENOTCONN   this process is not attached to a backplane;
 *   -EHOSTDOWN  no host server runs (slot 0 is free, dead or not serving),
 *               or it died before it replied;
 *   -ETIMEDOUT  the host server did not reply within chm_host_timeout();
 *   -EBUSY      its request ring stayed full for the whole timeout;
 *   -EPERM      called from an interrupt handler, or the server's slot
 *               failed the identity check;
 *   -errno      what the host's own call returned (-ENOENT, -EACCES...).
 * Under global error handling (chimera/err.h) nothing is raised: file
 * errors are ordinary outcomes the caller is expected to handle. */
#ifndef CHIMERA_XFS_H
#define CHIMERA_XFS_H

#include "chimera/status.h"

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Open flags: one of RDONLY, WRONLY, RDWR, or'ed with the others. The
 * values are Chimera's own (they cross processors). */
#define CHM_XFS_RDONLY 0x0
#define CHM_XFS_WRONLY 0x1
#define CHM_XFS_RDWR   0x2
#define CHM_XFS_CREAT  0x10
#define CHM_XFS_TRUNC  0x20
#define CHM_XFS_APPEND 0x40
#define CHM_XFS_EXCL   0x80

/* Open handles per client process at most. */
#define CHM_XFS_OPEN_MAX 256

typedef struct chm_xfs_stat {
    uint64_t size;      /* bytes */
    uint64_t mtime_ns;  /* last modification, ns since the epoch */
    uint32_t mode;      /* type and permission bits as stat(2)'s st_mode */
} chm_xfs_stat_t;

/* Open the host file `path` with `flags` (CHM_XFS_*), creating it with
 * `mode` (permission bits, e.g. 0644) under CHM_XFS_CREAT. Returns a
 * handle >= 0 for the other calls.
 * Errors: -EINVAL path NULL or empty or flags unknown; -EXDEV the path
 * leads out of the host server's root (absolute, "..", a symbolic link);
 * -EMFILE CHM_XFS_OPEN_MAX handles open; -ENAMETOOLONG the path does not
 * fit one request; the host's open(2) errors. */
CHM_CHECK int chm_xfs_open(const char* path, int flags, unsigned mode);

/* Close a handle. Errors: -EBADF not a handle of this process. */
CHM_CHECK int chm_xfs_close(int fd);

/* Read up to `n` bytes at the handle's position (which moves on), or at
 * `offset` with chm_xfs_pread (the position stays). Returns the bytes read,
 * 0 at end of file. Requests of more than 256 KiB are split; a short read of
 * one part ends the call.
 * Errors: -EBADF; -EFAULT buf NULL with n > 0; -EINVAL n > INT32_MAX or
 * offset < 0; the host's read(2) errors. */
CHM_CHECK int64_t chm_xfs_read(int fd, void* buf, size_t n);
CHM_CHECK int64_t chm_xfs_pread(int fd, void* buf, size_t n, int64_t offset);

/* Write `n` bytes at the position (or at `offset`). Returns the bytes
 * written. Errors as chm_xfs_read, and the host's write(2) errors. */
CHM_CHECK int64_t chm_xfs_write(int fd, const void* buf, size_t n);
CHM_CHECK int64_t chm_xfs_pwrite(int fd, const void* buf, size_t n, int64_t offset);

/* Move the position as lseek(2) (whence SEEK_SET, SEEK_CUR, SEEK_END);
 * returns the new position. Errors: -EBADF; -EINVAL bad whence or a
 * negative result. */
CHM_CHECK int64_t chm_xfs_lseek(int fd, int64_t offset, int whence);

/* What the host says about `path` (links followed, beneath the root) or
 * an open handle. Errors: -EFAULT out NULL; as chm_xfs_open; -EBADF. */
CHM_CHECK int chm_xfs_stat(const char* path, chm_xfs_stat_t* out);
CHM_CHECK int chm_xfs_fstat(int fd, chm_xfs_stat_t* out);

/* ioctl(2) on the host's descriptor: `arg` (arg_size bytes, at most 256)
 * is passed in and copied back. Returns ioctl's non-negative result.
 * Errors: -EBADF; -EINVAL arg_size > 256 or arg NULL with arg_size > 0;
 * the host's ioctl errors (-ENOTTY: not for this file). */
CHM_CHECK int chm_xfs_ioctl(int fd, unsigned long request, void* arg, size_t arg_size);

/* Buffered stdio over the extended file system: a FILE* (fopencookie) for
 * fprintf, fgets, fread, fseek... Mode as fopen(3) ("r", "w", "a", "r+",
 * "w+", "a+"). NULL on error, with errno set and chm_err_last()
 * saying why. fclose closes the handle. */
FILE* chm_xfs_fopen(const char* path, const char* mode);

/* What the last failing chm_xfs_* or chm_host_* call of this thread said,
 * or "". The tasks of an RTPU share its one thread: read it right after
 * the failing call, before the task can be preempted by another that
 * fails too.
 * chm_err_last() (err.h) gives the same text per task, whatever the
 * subsystem: use it; this call is kept for one release (CHANGELOG.md). */
const char* chm_xfs_last_error(void);

#ifdef __cplusplus
}
#endif
#endif
