/* Chimera backplane: the one mmap'd file that every RTPU and host process
 * of a system shares, as Chimera II's boards shared a VMEbus. It holds the
 * RTPU table, express-mail rings, the name registry, one local-memory
 * window per RTPU and common memory (docs/backplane.md, "Backplane").
 *
 * A process attaches once: a chimera-rtpu process joins as RTPU n
 * (chm_bp_join), any other program attaches as a host (chm_bp_attach_host).
 * Attaching starts a monitor thread that detects a dead peer within 50 ms
 * (pidfd, or /proc polling where pidfd_open is missing) and recovers it:
 * its locks, its half-finished changes, its attachments. Restarting the
 * same RTPU number after a crash needs no cleanup.
 *
 * Every function returns 0 or a negative errno-style status; after an
 * error, chm_err_last() says what failed, naming the file and field. */
#ifndef CHIMERA_BP_H
#define CHIMERA_BP_H

#include "chimera/status.h"

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define CHM_BP_NAME_MAX 31     /* RTPU and object names, without the NUL */
#define CHM_BP_MAX_SLOTS 32    /* RTPU table entries at most */
#define CHM_BP_ENV "CHIMERA_BACKPLANE"  /* overrides the default path */

/* Sizes of a new backplane. All sizes in bytes. */
typedef struct chm_bp_config {
    uint32_t rtpu_slots;        /* 2..32; slot 0 is the host server (default 32) */
    uint32_t ring_records;      /* express-mail records per RTPU (1..4096, default 64) */
    uint32_t ring_record_size;  /* bytes per record, multiple of 16 (16..65536, default 1024) */
    uint32_t local_window_size; /* each RTPU's local memory, multiple of 4096 (default 256 KiB) */
    uint32_t common_size;       /* common memory, multiple of 4096, >= 4096 (default 8 MiB) */
    uint32_t registry_capacity; /* named objects (1..65536, default 256) */
    uint32_t mode;              /* file permissions (default 0600); group write and
                                 * any bit for others are refused (-EINVAL) */
    int32_t group;              /* -1 (default): the file is the creator's alone;
                                 * a gid: the file is made mode 0660 with that
                                 * group, and its members may attach */
} chm_bp_config_t;

/* Fill `cfg` with the defaults above. */
void chm_bp_config_init(chm_bp_config_t* cfg);

/* Write the default backplane path into buf: $CHIMERA_BACKPLANE if set,
 * else <default directory>/backplane.bp (chm_bp_default_dir). Nothing is
 * created. Errors: -EINVAL NULL buf; -ENAMETOOLONG it does not fit in len
 * bytes. */
CHM_CHECK int chm_bp_default_path(char* buf, size_t len);

/* Write this user's directory for the default backplane and its logs into
 * buf: $XDG_RUNTIME_DIR/chimera when XDG_RUNTIME_DIR names a directory
 * owned by the caller, else /dev/shm/chimera-<uid>. Nothing is created.
 * Errors: -EINVAL NULL buf; -ENAMETOOLONG. */
CHM_CHECK int chm_bp_default_dir(char* buf, size_t len);

/* Check that `dir` is a directory only the caller can use: not a symbolic
 * link (lstat), owned by the caller's effective uid, no permission for the
 * group or others. With `create` != 0 it is made first (mode 0700) when
 * missing. chm_bp_create, every attach and chimera's commands run this on
 * the default directory, so a directory another user made first (a
 * squatter) is refused, never used. Errors (chm_err_last names the
 * directory, its owner and mode, and the fix): -ELOOP a symbolic link;
 * -ENOTDIR not a directory; -EPERM another owner or group/other access;
 * -ENOENT missing (create == 0); other -errno from mkdir/lstat. */
CHM_CHECK int chm_bp_check_dir(const char* dir, int create);

/* Check, without attaching, that this process may attach the backplane at
 * `path` (NULL: default), the check every attach makes: the file is opened
 * without following a final symbolic link and fstat'ed; it must be a
 * regular file owned by the caller's effective uid (root attaches files
 * root owns, and no one else's), with no permission for others, and
 * group-writable only when it was created for that group (config.group:
 * mode 0660), in which case members of the group may attach too; in the
 * default directory, that directory must pass chm_bp_check_dir. Then the
 * header is validated. Errors (chm_err_last names the file, its owner
 * and mode, and the fix): -ELOOP a symbolic link; -EPERM another owner, or
 * a mode that lets others (or, not made for it, the group) write;
 * -EBADMSG not a regular file, or not a valid backplane; -ENOENT; other
 * -errno from open. */
CHM_CHECK int chm_bp_check_file(const char* path);

/* Create a backplane file at `path` (NULL: the default path). The whole
 * file is built and its space reserved (posix_fallocate) under a temporary
 * name in the same directory, then published atomically: an opener never
 * sees a half-built file, and of two creators racing one gets -EEXIST.
 * Errors: -EEXIST the path exists; -EINVAL a config field out of range;
 * -EINVAL also for a mode attaching would refuse (group write without
 * config.group, any bit for others); -EPERM config.group is not one of the
 * caller's groups, or the default directory is not the caller's alone
 * (chm_bp_check_dir; it is created when missing);
 * -EFBIG the layout reaches 4 GiB, or the file size limit; -ENOSPC no room
 * (a full disk fails here, never later with SIGBUS); other -errno from
 * open/fallocate/mmap/link. Nothing is left behind on error. */
CHM_CHECK int chm_bp_create(const char* path, const chm_bp_config_t* cfg);

/* Validate the backplane file at `path` (NULL: default) without attaching:
 * the header, the RTPU table, the express-mail rings, every arena's header
 * and block chain (except one a process holds locked), every registry
 * entry (payload inside its arena without 32-bit wrap, an allocated block)
 * and every live message queue and remote semaphore (geometry, indices,
 * records). Read-only; `chimera start` and `chimera status` run it first.
 * Errors: -EBADMSG the file or an object in it is corrupt, and
 * chm_err_last() names the file, the structure and the field;
 * -ENOENT no file; other -errno from open/mmap. */
CHM_CHECK int chm_bp_validate(const char* path);

/* Join the backplane at `path` (NULL: default) as RTPU `rtpu`
 * (0..slots-1; 0 is the host server), named `name` (NULL: "rtpu<n>").
 * A slot left by a dead process (or being recovered) is recovered first and
 * taken with the next generation. The calling thread is recorded as the
 * RTPU's kernel thread (target of directed signals).
 * Errors: -EBUSY this process is already attached, or the slot belongs to a
 * live process; -ECHRNG rtpu out of range; -ENAMETOOLONG; -ENOENT no file;
 * -ELOOP, -EPERM the file may not be attached (chm_bp_check_file);
 * -EBADMSG not a backplane, another layout version, or a structure in it
 * is corrupt (a slot state or kind, a ring's geometry, an arena header, a
 * registry entry's payload: see chm_err_last, which names the field);
 * -ETIMEDOUT a recovery of that slot by another
 * process did not finish within 5 s; other -errno from open/mmap. */
CHM_CHECK int chm_bp_join(const char* path, int rtpu, const char* name);

/* Attach an ordinary program as a host process: it takes the highest free
 * slot (RTPU numbers count up from 1, hosts fill from the top). *slot_out
 * (may be NULL) receives the slot. Errors as chm_bp_join, and -ENOSPC when
 * every slot belongs to a live process. */
CHM_CHECK int chm_bp_attach_host(const char* path, const char* name, int* slot_out);

/* Leave cleanly: stop the monitor thread, drop this process's shared
 * memory attachments, mark the slot FREE and unmap. Objects created by
 * this process stay until destroyed; locks it still holds pass to their
 * next locker with -EOWNERDEAD. exit() does this by itself; a process
 * that is killed or calls _exit() is recovered as dead by the others.
 * No other thread of the process may use the backplane meanwhile.
 * Errors: -ENOTCONN not attached. */
CHM_CHECK int chm_bp_leave(void);

/* This process's slot, or -ENOTCONN. */
CHM_CHECK int chm_bp_self(void);

/* What the last failing chm_bp_* / chm_shm_* call of this thread said, or
 * "" when none failed yet.
 * chm_err_last() (err.h) gives the same text per task, whatever the
 * subsystem: use it; this call is kept for one release (CHANGELOG.md). */
const char* chm_bp_last_error(void);

/* Global error handling of IPC (chimera/err.h). A task with global handling
 * on (chm_err_global) gets every failing remote-semaphore (chm_rsem_*),
 * message-queue (chm_msgq_*), shared-memory (chm_shm_*) and spin-lock
 * (chm_spin_*) call whose status means a bug or a missing resource as an
 * error signal of module "ipc": code = the errno value (EINVAL, ENOENT,
 * ENOTCONN, ECHRNG, EEXIST, ENAMETOOLONG, ENOMEM, ENOSPC, EMSGSIZE,
 * EPERM, ESRCH, EBADMSG, ENOTRECOVERABLE, EBADF, EFAULT), detail
 * = the chm_err_last() message when the call left one. It is raised
 * when the call returns, holding no backplane lock; the default handler
 * prints one line and aborts only the task; a handler that continues makes
 * the call return its status, as with handling off. Outcomes are never
 * raised: -ETIMEDOUT, -EAGAIN, -EINTR, -EOWNERDEAD, -EIDRM, -EOVERFLOW,
 * -EBUSY and -EDEADLK. Host threads (not tasks) always get the status.
 * Returns the module's id (registered on first use) or a negative status. */
CHM_CHECK int chm_ipc_err_module(void);

enum chm_bp_slot_state {
    CHM_BP_FREE = 0, CHM_BP_JOINING = 1, CHM_BP_RUNNING = 2, CHM_BP_LEAVING = 3,
    CHM_BP_DEAD = 4, CHM_BP_RECOVERING = 5
};
enum chm_bp_slot_kind { CHM_BP_KIND_NONE = 0, CHM_BP_KIND_RTPU = 1, CHM_BP_KIND_HOST = 2 };

typedef struct chm_bp_slot_info {
    enum chm_bp_slot_state state;
    enum chm_bp_slot_kind kind;
    uint32_t generation;    /* grows on every join of the slot */
    int32_t pid;            /* 0 when free */
    int32_t tid;            /* the RTPU's kernel thread */
    uint32_t heartbeat_age_ms; /* since its monitor thread last beat */
    char name[CHM_BP_NAME_MAX + 1];
} chm_bp_slot_info_t;

typedef struct chm_bp_status {
    uint32_t slots;              /* RTPU table entries */
    int32_t self;                /* this process's slot */
    uint64_t created_ns;         /* CLOCK_REALTIME of creation */
    uint32_t file_size;
    uint32_t objects;            /* live named objects */
    uint32_t registry_capacity;
    uint32_t common_size, common_free;  /* bytes */
    uint32_t recoveries;         /* dead slots recovered since creation */
    chm_bp_slot_info_t slot[CHM_BP_MAX_SLOTS];
} chm_bp_status_t;

/* Snapshot of the attached backplane's RTPU table and usage (racy by
 * nature: each slot is read once). Errors: -EINVAL NULL; -ENOTCONN. */
CHM_CHECK int chm_bp_status(chm_bp_status_t* out);

/* Kinds of named objects (chm_bp_object_t.kind). */
enum chm_bp_object_kind {
    CHM_BP_OBJ_SHM = 1,    /* shared memory segment (chimera/shm.h) */
    CHM_BP_OBJ_RSEM = 2,   /* remote semaphore (chimera/rsem.h) */
    CHM_BP_OBJ_MSGQ = 3,   /* message queue (chimera/msgq.h) */
    CHM_BP_OBJ_SVARS = 4   /* the state-variable table (chimera/svar.h) */
};

/* One named object of the backplane, as its registry entry says. */
typedef struct chm_bp_object {
    char name[CHM_BP_NAME_MAX + 1];
    uint32_t kind;      /* enum chm_bp_object_kind (another number: a kind
                         * this version does not know) */
    int32_t where;      /* -1: common memory; else the RTPU slot whose local
                         * window holds it */
    uint32_t size;      /* bytes of storage */
    int32_t creator;    /* slot of the process that created it (-1: unknown) */
    uint32_t attached;  /* bit s: the process in slot s has it open */
} chm_bp_object_t;

/* The live named objects of the attached backplane, in registry order: up
 * to `max` go into out[]. Returns how many were filled (>= 0); *total (may
 * be NULL) receives how many are live. Each entry is read whole (retried
 * while a process changes it); an entry whose kind, name or place no
 * process could have made is left out (the file is untrusted: open an
 * object with its subsystem's call to have it validated). Racy by nature:
 * objects created or destroyed meanwhile may be missed.
 * Errors: -EINVAL max < 0, or out NULL with max > 0; -ENOTCONN not
 * attached. */
CHM_CHECK int chm_bp_objects(chm_bp_object_t* out, int max, int* total);

#ifdef __cplusplus
}
#endif
#endif
