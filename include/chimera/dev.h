/* Chimera device drivers, level 1: a driver table with open, close, read,
 * write, ioctl and mmap; applications open devices by name.
 *
 * A driver registers a name and an operations table; chm_dev_open(name)
 * returns a descriptor. Descriptors belong to the RTPU (the process) and are
 * generation-tagged: a descriptor that was closed, or one that was never
 * returned by chm_dev_open, is refused with CHM_EDEV_BADF and never reaches
 * a driver. Descriptors are >= 256, so a UNIX file descriptor passed by
 * mistake is refused too.
 *
 * Every call returns 0 (or a byte count / new descriptor) or a negative
 * status; none crashes on bad input. Every failing call also records a
 * message naming the problem (device, request, offset), readable with
 * chm_err_last(); with global error handling on, the failure is
 * raised as an error signal of module "dev" (see chm_dev_err_module).
 *
 * Calling context: any thread. On the kernel thread the driver call runs
 * with the interrupt mask held (a driver operation is never preempted half
 * way), so drivers must not block for long; a blocking read from a task
 * blocks the whole RTPU (use CHM_DEV_NONBLOCK or a timeout). */
#ifndef CHIMERA_DEV_H
#define CHIMERA_DEV_H

#include "chimera/status.h"

#include <errno.h>
#include <stddef.h>
#include <stdint.h>

#include "chimera/task.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Status codes (negative errno values, so they read as UNIX errors). */
#define CHM_EDEV_NODEV   (-ENODEV)     /* no device registered under that name */
#define CHM_EDEV_BADF    (-EBADF)      /* descriptor not open: closed, stale or never issued */
#define CHM_EDEV_NOTTY   (-ENOTTY)     /* ioctl request unknown to the device */
#define CHM_EDEV_RANGE   (-ENXIO)      /* offset at or past the end of the device's range */
#define CHM_EDEV_NOTSUP  (-EOPNOTSUPP) /* the device has no such operation (e.g. no mmap) */
#define CHM_EDEV_ACCES   (-EACCES)     /* not opened for that direction, or a read-only register */
#define CHM_EDEV_EXIST   (-EEXIST)     /* a device with that name is already registered */
#define CHM_EDEV_BUSY    (-EBUSY)      /* unregister while descriptors are open */
#define CHM_EDEV_MFILE   (-EMFILE)     /* the descriptor table is full */
#define CHM_EDEV_INVAL   (-EINVAL)     /* bad argument (NULL, bad flags, misaligned access) */

#define CHM_DEV_NAME_MAX 31       /* longest device name */
#define CHM_DEV_MAX_DEVICES 64    /* registered devices at once */
#define CHM_DEV_MAX_OPEN 256      /* open descriptors per RTPU */

/* chm_dev_open flags. */
#define CHM_DEV_READ     0x1
#define CHM_DEV_WRITE    0x2
#define CHM_DEV_RDWR     (CHM_DEV_READ | CHM_DEV_WRITE)
#define CHM_DEV_NONBLOCK 0x4      /* reads and writes never wait (stream devices) */

/* mmap protections (as PROT_READ / PROT_WRITE). */
#define CHM_DEV_PROT_READ  0x1
#define CHM_DEV_PROT_WRITE 0x2

/* ioctl requests every device may answer. Requests 0x0000-0x0fff are the
 * level-1 generic ones, 0x1000-0x1fff level 2 (chimera/sensor.h), and
 * 0x8000 upward are private to a driver. */
#define CHM_DEV_IOC_EVENT_FD 0x0001  /* arg int*: a file descriptor that becomes
                                      * readable when the device has new data or
                                      * raises its line (drain it by reading);
                                      * what interrupt handlers attach to */
#define CHM_DEV_IOC_TIME     0x0002  /* arg uint64_t*: the device's clock, ns */

/* What a driver implements. `ctx` is the pointer given at registration;
 * `inst` is what open stored for this descriptor. Offsets are checked by
 * level 1 against the range that open reported before read/write/mmap are
 * called, so drivers see only offsets inside it. Return 0 / a byte count,
 * or a negative status. Drivers must be safe for concurrent calls on
 * different descriptors, and for a read and a write at once on one. */
typedef struct chm_dev_ops {
    /* Required. Create the per-descriptor instance. *range: the size in
     * bytes of the device's register space; 0 for a stream device (reads
     * and writes ignore the offset). */
    int (*open)(void* ctx, int flags, void** inst, uint64_t* range);
    /* Required. Release the instance; an actuator stops safely here. */
    int (*close)(void* inst);
    /* Optional (NULL: CHM_EDEV_NOTSUP). */
    int64_t (*read)(void* inst, void* buf, size_t n, uint64_t off);
    int64_t (*write)(void* inst, const void* buf, size_t n, uint64_t off);
    /* Optional. Unknown requests: return CHM_EDEV_NOTTY. */
    int (*ioctl)(void* inst, unsigned long req, void* arg);
    /* Optional: map [off, off+len) of the register space; munmap undoes it
     * (level 1 calls it for every mapping still held at close). */
    int (*mmap)(void* inst, uint64_t off, size_t len, int prot, void** addr);
    int (*munmap)(void* inst, void* addr, size_t len);
} chm_dev_ops_t;

/* Register a driver under `name` (copied). `ops` must stay valid until
 * chm_dev_unregister; `ctx` is handed to ops->open.
 * Errors: CHM_EDEV_INVAL (NULL, empty name, no open/close);
 * -ENAMETOOLONG; CHM_EDEV_EXIST; -ENOSPC (CHM_DEV_MAX_DEVICES reached). */
CHM_CHECK int chm_dev_register(const char* name, const chm_dev_ops_t* ops, void* ctx);

/* Remove a driver. Errors: CHM_EDEV_NODEV; CHM_EDEV_BUSY while a
 * descriptor on it is open (nothing is changed). */
CHM_CHECK int chm_dev_unregister(const char* name);

/* Open the device `name`. Returns a descriptor (>= 256) owned by the
 * calling task (chm_task_self(); CHM_TID_NONE outside a task).
 * Errors: CHM_EDEV_NODEV; CHM_EDEV_INVAL (NULL name, no direction or
 * unknown flags); CHM_EDEV_MFILE; or the driver's open status. */
CHM_CHECK int chm_dev_open(const char* name, int flags);

/* Close a descriptor. The driver's close runs once the last call still in
 * progress on it returns. Errors: CHM_EDEV_BADF (also on a second close). */
CHM_CHECK int chm_dev_close(int dd);

/* Read / write at the descriptor's position and advance it (stream
 * devices: no position). Returns bytes moved (a transfer that crosses the
 * end of the range is cut short there), or CHM_EDEV_BADF, CHM_EDEV_ACCES
 * (not opened for that direction), CHM_EDEV_RANGE (position at or past the
 * end of the range), CHM_EDEV_NOTSUP, CHM_EDEV_INVAL (NULL buffer), -EAGAIN
 * (non-blocking, nothing ready) or the driver's status. */
CHM_CHECK int64_t chm_dev_read(int dd, void* buf, size_t n);
CHM_CHECK int64_t chm_dev_write(int dd, const void* buf, size_t n);

/* As read / write at offset `off`, leaving the position alone. */
CHM_CHECK int64_t chm_dev_pread(int dd, void* buf, size_t n, uint64_t off);
CHM_CHECK int64_t chm_dev_pwrite(int dd, const void* buf, size_t n, uint64_t off);

/* Move the position (whence: SEEK_SET, SEEK_CUR, SEEK_END). Returns the
 * new position. Errors: CHM_EDEV_BADF; CHM_EDEV_NOTSUP on a stream device;
 * CHM_EDEV_RANGE for a position below 0 or past the end of the range;
 * CHM_EDEV_INVAL bad whence. */
CHM_CHECK int64_t chm_dev_lseek(int dd, int64_t off, int whence);

/* Device control. Errors: CHM_EDEV_BADF; CHM_EDEV_NOTTY (request unknown
 * to the device; also for a device without ioctl); or the driver's. */
CHM_CHECK int chm_dev_ioctl(int dd, unsigned long req, void* arg);

/* Map [off, off+len) of the device's register space into memory; *addr
 * receives the address. Unmapped by chm_dev_munmap or at close.
 * Errors: CHM_EDEV_BADF; CHM_EDEV_NOTSUP; CHM_EDEV_RANGE (off+len past the
 * range, or len 0); CHM_EDEV_ACCES (write mapping of a read-only
 * descriptor); CHM_EDEV_INVAL; -ENOSPC (8 mappings per descriptor). */
CHM_CHECK int chm_dev_mmap(int dd, uint64_t off, size_t len, int prot, void** addr);
/* Errors: CHM_EDEV_BADF; CHM_EDEV_INVAL (not a mapping of this descriptor). */
CHM_CHECK int chm_dev_munmap(int dd, void* addr, size_t len);

/* The readable-on-event file descriptor of the device (CHM_DEV_IOC_EVENT_FD).
 * Returns it (>= 0), or CHM_EDEV_BADF / CHM_EDEV_NOTTY. */
CHM_CHECK int chm_dev_event_fd(int dd);

/* Name of the device behind a descriptor (valid while it is open), or NULL. */
const char* chm_dev_name(int dd);

/* Hook for the error layer and the kernel: the task `task` is being
 * aborted. Stops every actuator it opened (safe stop) and closes every
 * descriptor it owns. Returns the number of descriptors closed. Any
 * context except a signal handler. */
int chm_dev_task_abort(chm_tid_t task);

/* Safe-stop every open actuator of the RTPU (fail-stop, shutdown). Returns
 * how many were stopped. */
CHM_CHECK int chm_dev_safe_stop_all(void);

/* Returns the number of open descriptors (tests: nothing leaked). Never
 * fails. */
int chm_dev_open_count(void);

/* The message of the last failing device call on this thread ("" if none):
 * names the call, the device and the problem.
 * chm_err_last() (err.h) gives the same text per task, whatever the
 * subsystem: use it; this call is kept for one release (CHANGELOG.md). */
const char* chm_dev_last_error(void);

/* Error signals (chimera/err.h). A task with global error handling on
 * gets every refusal above as an error signal of module "dev" (code: the
 * errno value, e.g. ENODEV; detail: the chm_err_last() message),
 * raised when the call returns, holding nothing; a handler that continues
 * makes the call return its status as when handling is off. Outcomes
 * (-EAGAIN, -ETIMEDOUT, -EINTR) and CHM_ACT_CLAMPED are never raised.
 * Returns the module's id (registered on first use) or a negative status. */
CHM_CHECK int chm_dev_err_module(void);

/* Short text for a status ("no such device", ...). */
const char* chm_dev_strerror(int status);

#ifdef __cplusplus
}
#endif
#endif
