/* Chimera priority message queues: named queues of typed, variable-length
 * messages in backplane memory (common memory or one RTPU's local window),
 * used by tasks on every RTPU and by host processes and their threads.
 *
 * A message is a 32-bit type, a priority (0..CHM_MSGQ_PRIO_MAX, higher is
 * more urgent), the sending RTPU's slot and 0..max_msg bytes. A queue
 * hands messages out first-in-first-out, last-in-first-out or highest
 * priority first (first-in-first-out among equal priorities), as chosen at
 * creation. Its capacity is a number of messages and, optionally, a number
 * of payload bytes; each message occupies one slot of max_msg bytes.
 *
 * Sending and receiving never go through express mail: an operation that
 * need not wait takes the queue's robust lock once and copies the message
 * (no system call). One that must wait parks only the calling task on an
 * RTPU (its RTPU keeps running its other tasks) and sleeps on a futex in
 * any other thread; the peer that makes room or a message wakes the most
 * urgent waiter (highest task priority, then first come; host threads wait
 * at priority 0) through its RTPU's mailbox interrupt or the futex.
 * An RTPU process must have bound its kernel to the backplane
 * (chimera-rtpu does) for its tasks to be woken from other processes.
 *
 * A process that dies (kill -9) in the middle of a queue operation is
 * recovered by the survivors: its waiters are removed, a lock it held
 * passes on, and a queue it left half-changed is rebuilt from its message
 * slots (a message it was sending is either fully queued or absent; one it
 * was receiving stays queued). A queue whose slots were damaged beyond
 * that is marked broken and every later call on it fails with
 * -ENOTRECOVERABLE.
 *
 * Every call returns 0 (receive: the message length) or a negative
 * errno-style status; chm_bp_last_error() then says what was wrong.
 *
 * Errors under global handling (chimera/err.h): the statuses meaning a bug
 * or a missing resource (-EINVAL, -ENOENT, -ENOTCONN, -ECHRNG, -EEXIST,
 * -ENAMETOOLONG, -ENOMEM, -ENOSPC, -EMSGSIZE, -EPERM, -EBADMSG,
 * -ENOTRECOVERABLE...) are raised as error signals of module "ipc"
 * (chm_ipc_err_module, chimera/bp.h) when a task with global handling on
 * gets them; outcomes (-EAGAIN, -ETIMEDOUT, -EINTR, -EIDRM, -EOWNERDEAD)
 * are only returned. */
#ifndef CHIMERA_MSGQ_H
#define CHIMERA_MSGQ_H

#include "chimera/status.h"

#include <stddef.h>
#include <stdint.h>

#include "chimera/kernel.h" /* CHM_FOREVER, CHM_NO_WAIT */

#ifdef __cplusplus
extern "C" {
#endif

typedef struct chm_msgq chm_msgq_t; /* a handle: valid in this process */

#define CHM_MSGQ_COMMON (-1)          /* `where`: common memory */
#define CHM_MSGQ_PRIO_MAX 31          /* message priorities are 0..31 */
#define CHM_MSGQ_MSG_MAX (1u << 20)   /* max_msg at most 1 MiB */
#define CHM_MSGQ_COUNT_MAX (1u << 20) /* max_count at most 2^20 messages */
#define CHM_MSGQ_WAITERS_MAX 64       /* max_waiters at most */

/* Receive order. */
enum chm_msgq_order {
    CHM_MSGQ_FIFO = 0,     /* first in, first out (priority only carried) */
    CHM_MSGQ_LIFO = 1,     /* last in, first out */
    CHM_MSGQ_PRIORITY = 2  /* highest priority first; FIFO among equals */
};

typedef struct chm_msgq_attr {
    enum chm_msgq_order order;  /* default CHM_MSGQ_FIFO */
    uint32_t max_msg;      /* largest message, bytes: 1..CHM_MSGQ_MSG_MAX (default 256) */
    uint32_t max_count;    /* messages queued at most: 1..CHM_MSGQ_COUNT_MAX (default 64) */
    uint32_t max_bytes;    /* payload bytes queued at most; 0 = no limit but max_count
                            * (default 0); otherwise >= max_msg */
    uint32_t max_waiters;  /* callers that can wait with a wake-up record at once,
                            * 1..CHM_MSGQ_WAITERS_MAX (0 = 16); more wait by
                            * polling every millisecond */
} chm_msgq_attr_t;

/* What came with a received message. */
typedef struct chm_msgq_msg_info {
    uint32_t type;   /* as sent */
    uint32_t prio;   /* as sent */
    uint32_t len;    /* payload bytes */
    int32_t sender;  /* the sending process's backplane slot */
} chm_msgq_msg_info_t;

/* A snapshot of a queue (racy by nature; no lock taken). */
typedef struct chm_msgq_info {
    chm_msgq_attr_t attr;
    uint32_t count;             /* messages queued */
    uint32_t bytes;             /* payload bytes queued */
    uint32_t receivers_waiting; /* callers blocked in receive with a record */
    uint32_t senders_waiting;   /* callers blocked in send with a record */
    uint32_t sent, received;    /* messages in and out since creation (wrap) */
    int broken;                 /* 1: damaged beyond repair */
    int destroyed;              /* 1: chm_msgq_destroy was called */
} chm_msgq_info_t;

/* Fill `attr` with the defaults above. */
void chm_msgq_attr_init(chm_msgq_attr_t* attr);

/* Create the queue `name` (1..CHM_BP_NAME_MAX chars, unique among all named
 * backplane objects) in common memory (where = CHM_MSGQ_COMMON) or in RTPU
 * `where`'s local window, and open it: *out is this process's handle.
 * attr NULL: the defaults. Nothing is created on error.
 * Errors: -ENOTCONN not attached to a backplane; -EINVAL NULL or empty
 * name, NULL out, bad order, max_msg or max_count 0 or above its maximum,
 * max_bytes below max_msg, max_waiters above CHM_MSGQ_WAITERS_MAX;
 * -ENAMETOOLONG; -ECHRNG `where` is neither CHM_MSGQ_COMMON nor a slot;
 * -EEXIST the name is taken; -ENOMEM no room for the queue there;
 * -ENOSPC the registry is full; -ENOTRECOVERABLE that memory was damaged
 * by a process that died in it; -EBADMSG that memory's block chain is
 * corrupt (chm_bp_last_error names the block and field); -ETIMEDOUT a live
 * peer held the registry for more than 5 s. */
CHM_CHECK int chm_msgq_create(const char* name, const chm_msgq_attr_t* attr, int where, chm_msgq_t** out);

/* Open the queue `name` created by any process. Opening twice gives the
 * same handle and needs two closes.
 * The queue is validated first (its registry entry, its geometry and,
 * under its lock, every index and record) and the checked geometry kept in
 * this process: later calls address the queue with it.
 * Errors: -ENOTCONN; -EINVAL NULL name or out; -ENOENT no queue of that
 * name; -EBADMSG the queue is corrupt (chm_bp_last_error names the queue
 * and the field); -EDEADLK its lock was held past 5 s by a live peer;
 * -ETIMEDOUT. */
CHM_CHECK int chm_msgq_open(const char* name, chm_msgq_t** out);

/* Close this process's handle (the queue lives on until destroyed; a
 * destroyed queue's memory goes with its last open handle anywhere).
 * Errors: -ENOTCONN; -EINVAL not a queue opened by this process;
 * -ETIMEDOUT. */
CHM_CHECK int chm_msgq_close(chm_msgq_t* q);

/* Destroy the queue `name`: the name goes at once; every caller blocked on
 * it is woken and gets -EIDRM, as does every later send or receive through
 * a handle still open. Errors: -ENOTCONN; -EINVAL NULL; -ENOENT no such
 * queue; -ETIMEDOUT; -EDEADLK its lock was held past 5 s by a live peer. */
CHM_CHECK int chm_msgq_destroy(const char* name);

/* Timeouts (chimera/kernel.h): `timeout_ns` of the _timed calls is
 * relative; CHM_NO_WAIT does not wait (as the try_ calls), CHM_FOREVER
 * waits as long as it takes. Compatibility: it was int64_t with any
 * negative value meaning no limit; a -1 passed now converts to
 * UINT64_MAX, CHM_FOREVER, and still means no limit (other negative values
 * become huge timeouts). `deadline_ns` of the _until calls is an absolute
 * chm_time_now() value, for a loop that waits against fixed instants: a
 * task waits on its RTPU's kernel clock (exact on the virtual clock), a
 * host thread on CLOCK_MONOTONIC (chm_time_now()'s clock there). A
 * deadline already reached does not wait (the call still succeeds if it
 * can at once); CHM_FOREVER: no limit. */

/* Send a message of `len` bytes (data may be NULL when len is 0) with a
 * type and a priority. chm_msgq_send waits as long as the queue is full;
 * chm_msgq_send_timed at most `timeout_ns`; chm_msgq_send_until until
 * `deadline_ns`; chm_msgq_try_send never waits.
 * Errors: -EAGAIN full and not waiting (try, or CHM_NO_WAIT); -ETIMEDOUT
 * still full when the timeout ran out or the deadline came (a past one
 * included); -EMSGSIZE len > max_msg (or > max_bytes);
 * -EINVAL bad handle, NULL data with len > 0, prio > CHM_MSGQ_PRIO_MAX;
 * -EINTR a user signal (task) or a signal handler (thread) interrupted the
 * wait; -EIDRM the queue was destroyed; -ENOTRECOVERABLE the queue is
 * broken; -EDEADLK its lock was held past 5 s by a live peer; -EBADMSG an
 * index read from shared memory (the free list's head, a list's tail) is
 * out of range (the message is not sent); -ENOTCONN.
 * On any error nothing was queued. The try call (and CHM_NO_WAIT) never
 * waits for another process: its -EAGAIN also means the queue's lock is
 * held by a live peer that stalled inside a call (it spins at most 20 µs
 * for the lock; chm_err_last names the holder's slot and task). A timed
 * send (or one with a deadline) waits for that lock no longer than its
 * own limit: -ETIMEDOUT then; chm_msgq_send waits up to 5 s (-EDEADLK). */
CHM_CHECK int chm_msgq_send(chm_msgq_t* q, uint32_t type, uint32_t prio, const void* data, size_t len);
CHM_CHECK int chm_msgq_send_timed(chm_msgq_t* q, uint32_t type, uint32_t prio, const void* data, size_t len,
                        uint64_t timeout_ns);
CHM_CHECK int chm_msgq_send_until(chm_msgq_t* q, uint32_t type, uint32_t prio, const void* data, size_t len,
                        uint64_t deadline_ns);
CHM_CHECK int chm_msgq_try_send(chm_msgq_t* q, uint32_t type, uint32_t prio, const void* data, size_t len);

/* Receive the next message in the queue's order into buf (size bytes);
 * *info (may be NULL) receives its type, priority, length and sender.
 * Returns the message's length (>= 0). chm_msgq_receive waits as long as
 * the queue is empty; _timed at most `timeout_ns`; _until until
 * `deadline_ns` (see "Timeouts" above); try_receive never waits.
 * Errors: -EAGAIN empty and not waiting (try, or CHM_NO_WAIT); -ETIMEDOUT
 * still empty when the timeout ran out or the deadline came; -EMSGSIZE the next
 * message is longer than size (it stays queued; *info, if given, says its
 * length); -EINVAL bad handle, NULL buf with size > 0; -EINTR; -EIDRM;
 * -ENOTRECOVERABLE; -EDEADLK; -EBADMSG a list head or the message's length
 * read from shared memory is out of range; -ENOTCONN. On any error nothing
 * was taken. try_receive never waits for another process either (its
 * -EAGAIN: as chm_msgq_try_send's), nor _timed / _until past their limit
 * (-ETIMEDOUT). */
CHM_CHECK int chm_msgq_receive(chm_msgq_t* q, void* buf, size_t size, chm_msgq_msg_info_t* info);
CHM_CHECK int chm_msgq_receive_timed(chm_msgq_t* q, void* buf, size_t size, chm_msgq_msg_info_t* info,
                           uint64_t timeout_ns);
CHM_CHECK int chm_msgq_receive_until(chm_msgq_t* q, void* buf, size_t size, chm_msgq_msg_info_t* info,
                           uint64_t deadline_ns);
CHM_CHECK int chm_msgq_try_receive(chm_msgq_t* q, void* buf, size_t size, chm_msgq_msg_info_t* info);

/* A snapshot of the queue (its limits as its open checked them).
 * Errors: -EINVAL bad handle (one this process has not open) or NULL out;
 * -ENOTCONN. */
CHM_CHECK int chm_msgq_info(chm_msgq_t* q, chm_msgq_info_t* out);

#ifdef __cplusplus
}
#endif
#endif
