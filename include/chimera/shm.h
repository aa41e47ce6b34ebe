/* Chimera global shared memory: named segments in common memory or in one
 * RTPU's local-memory window of the backplane, attached by name from any
 * RTPU or host process. After attach a segment is plain memory: no software
 * sits between a task and its loads and stores.
 *
 * Requires this process to be attached to a backplane (chimera/bp.h).
 * Every function returns 0 or a negative errno-style status; after an
 * error chm_err_last() says what failed.
 *
 * Errors under global handling (chimera/err.h): the statuses meaning a bug
 * or a missing resource (-EINVAL, -ENOENT, -ENOTCONN, -ECHRNG, -EEXIST,
 * -ENAMETOOLONG, -ENOMEM, -ENOSPC, -EMSGSIZE, -EPERM, -EBADMSG,
 * -ENOTRECOVERABLE...) are raised as error signals of module "ipc"
 * (chm_ipc_err_module, chimera/bp.h) when a task with global handling on
 * gets them; -EDEADLK (the registry lock held past its bound by a live
 * process) is only returned. */
#ifndef CHIMERA_SHM_H
#define CHIMERA_SHM_H

#include "chimera/status.h"

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* `where` for a segment in common memory; otherwise an RTPU number. */
#define CHM_SHM_COMMON (-1)

/* Create the segment `name` (1..CHM_BP_NAME_MAX chars, unique among all
 * named backplane objects) of `size` bytes in common memory or in RTPU
 * `where`'s local window, zero-filled, 16-byte aligned, and attach it:
 * *out receives its address in this process.
 * Errors: -EINVAL NULL or empty name, size 0 or >= 4 GiB, NULL out;
 * -ENAMETOOLONG; -ECHRNG `where` is neither CHM_SHM_COMMON nor a slot;
 * -EEXIST the name is taken; -ENOMEM no room in that window;
 * -ENOSPC the registry is full; -ENOTRECOVERABLE that window was damaged
 * by a process that died in it; -EBADMSG that window's block chain is
 * corrupt (chm_err_last names the block and field); -ETIMEDOUT a live
 * peer held the registry for more than 5 s; -ENOTCONN not attached. */
CHM_CHECK int chm_shm_create(const char* name, size_t size, int where, void** out);

/* Attach the segment `name`: *out its address here, *size (may be NULL)
 * its size. Attaching twice gives the same address and needs two detaches.
 * Errors: -EINVAL NULL name or out; -ENOENT no segment of that name;
 * -EBADMSG its registry entry is corrupt: offset and size do not describe
 * an allocated block of its memory (chm_err_last names the field);
 * -ETIMEDOUT; -ENOTCONN. */
CHM_CHECK int chm_shm_attach(const char* name, void** out, size_t* size);

/* Detach a segment attached (or created) by this process, given the
 * address attach returned. A destroyed segment's memory is freed when its
 * last attachment anywhere goes. Errors: -EINVAL not a segment attached
 * here; -ETIMEDOUT; -ENOTCONN. */
CHM_CHECK int chm_shm_detach(void* addr);

/* Destroy the segment `name`: the name goes at once (a new segment may
 * take it); the memory stays valid for every process that has it attached
 * until each detaches (or leaves, or dies). Errors: -EINVAL NULL;
 * -ENOENT no such segment; -ETIMEDOUT; -ENOTCONN. */
CHM_CHECK int chm_shm_destroy(const char* name);

#ifdef __cplusplus
}
#endif
#endif
