// Express mail: each RTPU's ring of request records in the backplane (the
// region layout.hpp reserves), served by that RTPU's server task; replies
// go back in the same record. Public calls: include/chimera/rtpu.h.
//
// A record's life (the `state` word is seq << 4 | phase, so a party that
// holds an old view of a record can never change a later use of it):
//
//   FREE --claim (ring lock)--> WRITING --sender--> POSTED --server--> SERVING
//   SERVING --server--> REPLIED --sender reads--> FREE
//   sender gives up: POSTED -> FREE, SERVING -> ABANDONED (server frees it)
//   a dead owner's WRITING / POSTED / REPLIED / STALE record: reclaimed ->
//   FREE (by the server, or by a sender that finds the ring full); a new
//   server of the slot frees whatever its dead predecessor left SERVING or
//   ABANDONED.
//   a live owner's record WRITING for over kStaleWriteMs: -> STALE, which
//   nobody claims or serves; its owner frees it when it wakes (its post
//   fails, -ETIMEDOUT), or the reclaim when it dies. Not FREE: the owner
//   may be stalled in the middle of its writes, and a record handed to the
//   next sender would receive the rest of them over that sender's request.
//
// Only the claim takes the ring's robust lock (RingHeader::lock), and only
// for a scan and three stores: the owner token is written before the state
// leaves FREE, so a sender killed at any instruction leaves either a free
// record or one that names it. RingHeader words: head = claim sequence,
// tail = token of the RTPU whose server serves the ring (0: none),
// reserved[0] = requests served (statistics).
#pragma once

#include <cstddef>
#include <cstdint>

#include "chimera/task.h"
#include "ipc/backplane/backplane.hpp"

namespace chm::xmail {

enum Phase : std::uint32_t {
    kFree = 0, kWriting = 1, kPosted = 2, kServing = 3, kReplied = 4, kAbandoned = 5, kStale = 6
};
constexpr std::uint32_t make_state(std::uint32_t seq, Phase p) { return seq << 4 | p; }
constexpr Phase phase_of(std::uint32_t st) { return Phase(st & 0xF); }
constexpr std::uint32_t seq_of(std::uint32_t st) { return st >> 4; }

// The first 64 bytes of every ring record; the payload follows (request,
// then the reply in its place).
struct Record {
    bp::A32 state;        // seq << 4 | Phase
    bp::A32 owner;        // sender's token (layout.hpp), written before the claim
    bp::A32 stamp_ms;     // monotonic ms of the claim
    bp::A32 reply;        // futex word: 0 until the reply is in
    bp::A32 waiter_task;  // the sender's task id (ipc::WaiterId): it waits as a task; 0: the futex
    std::uint32_t kind;   // Kind
    std::int32_t status;  // the server's result: >= 0 or -errno
    std::uint32_t len;    // request bytes, then reply bytes
    std::uint32_t server; // token of the server that took it
    bp::A32 waiter_urgency;  // ipc::WaiterId::urgency
    std::uint32_t reserved[6];
};
static_assert(bp::kShared<Record> && sizeof(Record) == 64);
inline constexpr std::uint32_t kRecordMin = 128;   // CHM_RTPU_RECORD_MIN
inline constexpr std::uint32_t kStaleWriteMs = 2000;

enum Kind : std::uint32_t {
    kPing = 1, kSpawn, kSignal, kTasks, kFind, kDestroy, kStop, kServo, kHost, kKindEnd
};

// ------------------------------------------------------------ wire formats
// Fixed offsets on every target (m68k aligns 64-bit fields to 2 bytes, so
// every uint64_t sits at a multiple of 8 by construction).

struct PingReply {
    std::int32_t pid;
    std::uint32_t tasks;
    std::uint32_t policy;
    std::uint32_t served;
    std::uint64_t uptime_ns;
};
static_assert(sizeof(PingReply) == 24);

// SpawnRequest, then `text_len` bytes: path NUL, argv[0] NUL, ... argv[argc-1] NUL.
struct SpawnRequest {
    std::int32_t argc;
    std::uint32_t text_len;
};
// SpawnReply, then the loader's message (NUL-terminated) when it failed.
struct SpawnReply {
    std::int64_t tid;  // chm_tid_t
    std::int32_t program;
    std::int32_t pad;
};

struct TaskRequest {  // kSignal, kDestroy
    std::int64_t tid;  // chm_tid_t
    std::int32_t signo;
    std::int32_t pad;
};

struct FindRequest {
    char name[CHM_TASK_NAME_MAX + 1];
};

struct TasksRequest {
    std::uint32_t start;  // first task slot to look at
    std::uint32_t max;    // entries wanted at most
};
// One task of the list (chm_rtpu_task_t's figures). Its size travels in
// TasksReply::entry_size, so a sender and a server built from different
// versions of this struct refuse each other's pages (-EPROTO) instead of
// reading one layout as the other. 80 bytes until the worst-case figures
// were added, 128 until task ids became 64 bits.
struct TaskEntry {
    std::int64_t id;  // chm_tid_t
    std::uint32_t state;
    std::int32_t priority;
    std::uint32_t critical;
    std::uint32_t pad;
    std::uint64_t period_ns, cpu_ns, cycles, misses;
    std::uint64_t deadline_ns, wcet_ns;   // relative deadline, CPU estimate per cycle
    std::uint64_t worst_lateness_ns;      // worst completion after the deadline
    std::uint64_t worst_cycle_cpu_ns;     // worst CPU time of one cycle
    std::uint64_t stack_size, stack_high_water;  // bytes
    char name[CHM_TASK_NAME_MAX + 1];
};
static_assert(sizeof(TaskEntry) == 136);
// TasksReply, then `count` TaskEntry.
struct TasksReply {
    std::uint32_t total;  // tasks alive
    std::uint32_t next;   // slot to ask for next; kTasksEnd: that was all
    std::uint32_t count;
    std::uint32_t entry_size;  // sizeof(TaskEntry) of the server (0 before it was sent)
};
inline constexpr std::uint32_t kTasksEnd = 0xFFFFFFFFu;

struct StopRequest {
    std::int32_t code;
};

// ------------------------------------------------------------ sender side

// Send one request to RTPU `rtpu` and wait for its reply (bounded by
// timeout_ns). The reply's payload goes into reply[0..cap) and its length
// into *reply_len. Returns the server's status (>= 0 or -errno) or one of
// the transport errors in chimera/rtpu.h; `why` (thread-local, for
// chm_rtpu_last_error) is set on a transport error.
int call(int rtpu, Kind kind, const void* req, std::uint32_t len, void* reply, std::uint32_t cap,
         std::uint32_t* reply_len, std::uint64_t timeout_ns);

// call() in two halves, for a sender that keeps several requests in flight
// (the extended file system's read-ahead): post claims, writes and posts
// the record and rings the target (the transport errors of call); await
// waits for its reply exactly as call does; cancel gives a posted request
// up (the server may still carry it out; its reply is dropped). A Pending
// is used by one task at a time; `r` is nullptr when nothing is posted.
struct Pending {
    Record* r = nullptr;
    std::uint32_t seq = 0, rtpu = 0, status = 0;  // status: the target's slot word at post
    std::uint64_t deadline = 0, timeout_ns = 0;
};
int post(int rtpu, Kind kind, const void* req, std::uint32_t len, std::uint64_t timeout_ns, Pending* p);
int await(Pending* p, void* reply, std::uint32_t cap, std::uint32_t* reply_len);
void cancel(Pending* p);

// Reclaim records of `ring` whose owner died (freed) or whose live owner
// stalled mid-write (set STALE). Any process; returns the number changed.
unsigned reclaim(const bp::View& v, bp::RingHeader* ring);

// A departing process (chm_bp_leave) gives up every request `token` still
// has in any ring, as a sender that timed out would: not yet served ->
// FREE, being served -> ABANDONED (that server frees it), a reply never
// read -> FREE. Its tasks parked on a reply never run again, and the
// record would otherwise hold a slot of the target's ring until that
// server next wakes. Returns the number of records given up.
unsigned withdraw(const bp::View& v, std::uint32_t token);

// A record of a ring (index < capacity). Capacity and record size come
// from the process's validated layout (View::geo), never from the ring
// header in shared memory: attach checked that the two agree, and a header
// changed later cannot move a record outside the ring (a capacity or a
// record size of 0 once divided by zero and read outside the map).
inline std::uint32_t ring_capacity(const bp::View& v) { return v.geo().ring_records; }
inline std::uint32_t ring_record_size(const bp::View& v) { return v.geo().ring_record_size; }
inline Record* record_at(const bp::View& v, bp::RingHeader* ring, std::uint32_t i) {
    return reinterpret_cast<Record*>(reinterpret_cast<char*>(ring + 1) +
                                     std::size_t(i) * ring_record_size(v));
}
inline char* payload_of(Record* r) { return reinterpret_cast<char*>(r + 1); }

void set_error(const char* fmt, ...) __attribute__((format(printf, 1, 2)));

// ------------------------------------------------------------ server side

// A spawn request as the server reads it: pointers into the request.
inline constexpr int kSpawnArgsMax = 64;
struct SpawnArgs {
    const char* path;
    int argc;
    const char* argv[kSpawnArgsMax];
};
// Decode a kSpawn request of `len` bytes (a copy the server owns: it may
// hold anything a sender wrote). 0; -EINVAL shorter than its header, a
// text length beyond the request or 0, a text not NUL-terminated, fewer
// strings than argc says; -E2BIG more than kSpawnArgsMax arguments.
int decode_spawn(const char* req, std::uint32_t len, SpawnArgs* out);


// On the kernel thread of an RTPU that joined the backplane and bound its
// kernel (ipc::wake_bind_kernel), before chm_kernel_run: free what a dead
// predecessor left in this slot's ring, spawn the server task (`priority`)
// and install its interrupt handler (ipc::kVecExpressMail). Errors:
// -ENOTCONN not joined as an RTPU; -EMSGSIZE ring records below
// kRecordMin; -EBUSY already started; -ENOMEM; chm_task_spawn's errors.
int server_start(int priority);
// Stop serving (the ring's server word is cleared; later requests fail
// with -EHOSTDOWN once the slot is left). Kernel thread, after run.
void server_stop();
// The server task, or CHM_TID_NONE.
chm_tid_t server_task();

// ------------------------------------------------------------ deferred replies
// A request whose work blocks (the host server's file and program calls,
// src/host/) is not answered on the server task: a handler set for its kind
// takes a copy of the request and the record (still SERVING) and returns;
// some other thread of the process later answers with finish(). The sender
// waits as for any request, bounded by its own timeout and by the server's
// liveness. At most one handler per kind; set before server_start.
using DeferFn = void (*)(Record* r, std::uint32_t seq, std::uint32_t index, const char* req,
                         std::uint32_t len, std::uint32_t owner);
void set_deferred(Kind kind, DeferFn fn);
// Answer a deferred request from any thread of the serving process: the
// reply (n bytes, at most the record's payload room) and status go into the
// record, which becomes REPLIED and its sender is woken; a sender that gave
// up meanwhile (ABANDONED) gets nothing and the record is freed.
void finish(Record* r, std::uint32_t seq, int status, const void* reply, std::uint32_t n);

}  // namespace chm::xmail
