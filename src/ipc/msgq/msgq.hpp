// Message queues (include/chimera/msgq.h): the queue's layout in backplane
// memory and the internal calls shared by the files of this folder.
//
// A queue is the payload of a registry entry of kind kKindMsgQueue:
//   QueueHeader | max_count message slots | max_waiters waiter records
// One robust lock (QueueHeader::lock) guards all of it.
//
// Truth and derived state. What a dead holder can leave half-written is
// only ever *derived*: the per-level lists, the free list, the counters
// and the level mask are all rebuilt from the slots themselves, whose
// `state` word is the single store that commits a message (FREE ->
// QUEUED, written after the slot's contents) or releases it (QUEUED ->
// FREE, written after the contents were copied out). Each queued slot
// carries its sequence number, so the order is rebuilt too (repair.cpp).
//
// Waiter records: a caller that must wait takes a record (its token =
// RTPU slot and generation, task or futex waiter, priority, a ticket) and
// waits on the record's `word` with ipc::wait_word. A peer that makes a
// message (or room) grants the most urgent ungranted record of the other
// direction by storing its ticket into `word` under the lock and waking it
// (ipc::wake_granted) after unlocking. "Granted" means word == ticket, so
// a late wake that lands on a record already reused can only cause a
// spurious wake-up, never hide a real one. The waiter removes its own
// record; a dead waiter's record is removed by the recovery (or lazily by
// the next granter, which checks the token).
#pragma once

#include <cstddef>
#include <cstdint>

#include "chimera/msgq.h"
#include "ipc/backplane/backplane.hpp"
#include "ipc/wake/wake.hpp"

namespace chm::ipc::msgq {

using bp::A32;
using ipc::WaiterId;

inline constexpr std::uint32_t kMagic = 0x4D534751;  // "MSGQ"
inline constexpr std::uint32_t kLevels = 32;         // priorities 0..31
inline constexpr std::uint32_t kNil = 0xFFFFFFFFu;
inline constexpr std::uint32_t kSlotFree = 0x46524545;    // "FREE"
inline constexpr std::uint32_t kSlotQueued = 0x51554555;  // "QUEU"
inline constexpr std::uint32_t kDefaultWaiters = 16;
inline constexpr std::uint64_t kLockPollNs = 20'000;

enum Order : std::uint32_t { kFifo = 0, kLifo = 1, kPriority = 2 };
enum WaiterState : std::uint32_t { kWaiterFree = 0, kWaiterRecv = 1, kWaiterSend = 2 };

// Laid out by how it is used. Line 0 holds the lock and every word a send
// or a receive changes (FIFO and LIFO queues use level 0 only), so an
// operation that takes the lock has them too; the read-mostly geometry and
// flags follow in line 1, the lists of levels 1-31 after. With the lists
// and counters in three further lines, a message streamed across cores
// moved five lines each way (on a host that passes a line in ~220 ns:
// 700-900 ns a message).
struct QueueHeader {
    bp::Lock lock;              // guards everything below
    A32 count;                  // derived: queued messages
    A32 bytes;                  // derived: queued payload bytes
    A32 free_head;              // derived: free slot list
    A32 next_seq;               // sequence number of the next message
    A32 recv_waiting;           // records in state kWaiterRecv
    A32 send_waiting;           // records in state kWaiterSend
    A32 level_mask;             // derived: bit l = list l not empty
    A32 sent, received;         // statistics
    A32 next_ticket;            // ticket of the next waiter record (never 0)
    A32 head0, tail0;           // derived: level 0's list (head(0), tail(0))
    A32 magic;                  // kMagic, written last at creation
    std::uint32_t order;        // Order
    std::uint32_t max_msg;
    std::uint32_t max_count;    // number of slots
    std::uint32_t max_bytes;    // payload limit (max_count * max_msg when unset)
    std::uint32_t slot_size;    // sizeof(MsgSlot) + max_msg rounded up to 16
    std::uint32_t max_waiters;
    std::uint32_t slots_off;    // from the header
    std::uint32_t waiters_off;  // from the header
    std::uint32_t total_size;   // header + slots + waiters
    A32 broken;                 // 1: damaged beyond repair
    A32 destroyed;              // 1: chm_msgq_destroy ran
    A32 repairs;                // rebuilds after a dead holder
    A32 entry;                  // its registry index (written at create and open): finds Geo
    std::uint32_t reserved[2];
    A32 head_hi[kLevels - 1];   // derived: levels 1..31 (priority order)
    A32 tail_hi[kLevels - 1];
    std::uint32_t reserved_end[2];

    // The list of level l (< kLevels).
    A32& head(std::uint32_t l) { return l ? head_hi[l - 1] : head0; }
    A32& tail(std::uint32_t l) { return l ? tail_hi[l - 1] : tail0; }
    const A32& head(std::uint32_t l) const { return l ? head_hi[l - 1] : head0; }
    const A32& tail(std::uint32_t l) const { return l ? tail_hi[l - 1] : tail0; }
};

struct MsgSlot {
    A32 state;   // kSlotFree / kSlotQueued: the truth
    A32 next;    // derived: list link (slot index or kNil)
    A32 type;
    A32 len;
    A32 prio;
    A32 seq;     // order of arrival (wraps; compared by difference)
    A32 sender;  // sending slot
    std::uint32_t pad;
    // payload follows
};

struct Waiter {
    A32 word;    // 0 while waiting; == ticket when granted
    A32 state;   // WaiterState
    A32 ticket;  // this registration's number (never 0)
    A32 token;   // the waiter's owner token (slot and generation)
    A32 task;     // the parked task's id (ipc::WaiterId), 0: a futex waiter
    A32 prio;     // the waiter's priority (int32 stored as uint32)
    A32 urgency;  // ipc::WaiterId::urgency
    std::uint32_t pad;
};

static_assert(bp::kShared<QueueHeader> && sizeof(QueueHeader) == 384);
static_assert(offsetof(QueueHeader, tail0) + 4 == 64, "the lock, counters and level 0's list: one line");
static_assert(offsetof(QueueHeader, magic) == 64 && offsetof(QueueHeader, head_hi) == 128);
static_assert(bp::kShared<MsgSlot> && sizeof(MsgSlot) == 32);
static_assert(bp::kShared<Waiter> && sizeof(Waiter) == 32);

// Read-modify-write of a word only the lock holder changes: a load and a
// store (a relaxed fetch_add would still be a locked bus cycle).
inline std::uint32_t bump(A32& a, std::uint32_t delta) {
    const std::uint32_t old = a.load(std::memory_order_relaxed);
    a.store(old + delta, std::memory_order_relaxed);
    return old;
}
inline void set_bits(A32& a, std::uint32_t bits) {
    a.store(a.load(std::memory_order_relaxed) | bits, std::memory_order_relaxed);
}
inline void clear_bits(A32& a, std::uint32_t bits) {
    a.store(a.load(std::memory_order_relaxed) & ~bits, std::memory_order_relaxed);
}

// A queue's geometry, copied out of its header and validated (read_geometry):
// slots and records are addressed with this process-local copy only, so a
// header changed in shared memory after the check cannot move an access
// outside the queue. Kept per open queue in Attachment::objects.
struct Geo {
    std::uint32_t order, max_msg, max_count, max_bytes, slot_size, max_waiters, slots_off, waiters_off;
};
static_assert(sizeof(Geo) == sizeof(bp::Attachment::OpenObject::words));

inline MsgSlot* slot_at(QueueHeader* q, const Geo& g, std::uint32_t i) {
    return reinterpret_cast<MsgSlot*>(reinterpret_cast<char*>(q) + g.slots_off + std::size_t(i) * g.slot_size);
}
inline char* payload_of(MsgSlot* s) { return reinterpret_cast<char*>(s + 1); }
inline Waiter* waiter_at(QueueHeader* q, const Geo& g, std::uint32_t i) {
    return reinterpret_cast<Waiter*>(reinterpret_cast<char*>(q) + g.waiters_off) + i;
}
inline std::uint32_t level_of(const Geo& g, std::uint32_t prio) { return g.order == kPriority ? prio : 0; }

// Bytes a queue of these limits needs, or 0 when it does not fit in 4 GiB.
std::uint32_t queue_size(std::uint32_t max_msg, std::uint32_t max_count, std::uint32_t max_waiters);
// Lay out an (all-zero) queue; magic is written last.
void queue_init(QueueHeader* q, std::uint32_t order, std::uint32_t max_msg, std::uint32_t max_count,
                std::uint32_t max_bytes, std::uint32_t max_waiters);
// Copy the header's geometry into *g and check the copy against
// `payload_size` bytes: 0, or bp::kCorrupt with `why` naming the field.
int read_geometry(const QueueHeader* q, std::uint32_t payload_size, Geo* g, char* why, std::size_t n);
// With the lock held (or a quiescent file): every index and record of the
// queue against `g` (lists, free list, tails, mask, counters, slot states,
// lengths and priorities, waiter states). 0, or bp::kCorrupt with `why`
// naming the field. Bounded: O(max_count + max_waiters).
int validate_locked(QueueHeader* q, const Geo& g, char* why, std::size_t n);

// A wake-up to deliver after the lock is released.
struct Wake {
    std::uint32_t* word;
    std::uint32_t ticket, slot;
    WaiterId who;
};
// Wake-ups collected under the lock, delivered after it is released (a
// wake is a system call or a doorbell; the lock should not wait for it).
// One that finds no room is delivered at once.
struct Wakes {
    Wake* w;
    std::uint32_t cap, n = 0;
    void add(const Wake& x);
    void deliver();
};
template <std::uint32_t N>
struct WakeBuf : Wakes {
    Wake buf[N];
    WakeBuf() : Wakes{buf, N} {}
};

// Lock the queue for `me`. A lock robbed from a dead holder that left the
// queue mid-change is rebuilt first. 0; -EDEADLK a live holder kept it
// past bp::kInternalTimeoutNs; with a send's or receive's `limit`: for
// CHM_NO_WAIT (a try call) -EAGAIN a live holder kept it past
// bp::kTryLockNs, for a timeout or deadline nearer than 5 s -ETIMEDOUT it
// was held past that; -ENOTRECOVERABLE broken (the lock is not held then).
int lock_queue(const bp::View& v, QueueHeader* q, const Geo& g, std::uint32_t me,
               const WaitLimit* limit = nullptr);
void unlock_queue(QueueHeader* q);

// With the lock held: grant the most urgent ungranted waiter of `state`
// (kWaiterRecv or kWaiterSend), freeing records of dead waiters met on
// the way. Adds the wake-up to `out`; false when nobody was waiting.
bool grant_one_locked(const bp::View& v, QueueHeader* q, const Geo& g, std::uint32_t state, Wakes* out);
// Grant every waiter (destroy).
void grant_all_locked(QueueHeader* q, const Geo& g, Wakes* out);
// Free the records of a dead slot's waiters, passing on any grant they
// held so no message or room is left with waiters asleep.
void purge_token_locked(const bp::View& v, QueueHeader* q, const Geo& g, std::uint32_t token, Wakes* out);

// Rebuild every derived field from the slots (lock held, dirty). False,
// and the queue marked broken, when a slot or the header is damaged.
bool rebuild_locked(QueueHeader* q, const Geo& g);

// The recovery callback of kKindMsgQueue (bp::register_recovery); also
// the line for kBuiltinRecovery in backplane/recovery.cpp.
void recover(const bp::View& v, std::uint32_t entry_index, std::uint32_t dead_slot,
             std::uint32_t dead_gen, std::uint32_t recovery_token);
// Register `recover` in this process (idempotent, cheap).
void ensure_recovery_registered();

// Strict read-only check of one queue (tests, a later bpcheck): one
// Report line per problem, prefixed with `name`.
void check_queue(const bp::View& v, const QueueHeader* q, std::uint32_t payload_size,
                 const char* name, bp::Report& r);
// The header's messages, for errors: "message queue at offset N".
void set_corrupt(const bp::View& v, const QueueHeader* q, const char* fmt, ...) __attribute__((format(printf, 3, 4)));

}  // namespace chm::ipc::msgq
