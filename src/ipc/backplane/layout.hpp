// The backplane file's layout: every structure that lives in the shared
// file, with the constants that give it meaning. Fixed and versioned
// (kLayoutVersion): a change to anything here bumps the version, and an
// opener refuses a file of another version.
//
// Rules, all checked below at compile time:
//  * only offsets (uint32_t from the file base; the file is < 4 GiB) and
//    indices, never pointers: each process maps the file where it likes;
//  * every structure is standard-layout with fixed offsets and explicit
//    padding, so the layout is the same on x86-64, aarch64 and m68k (where
//    a uint32_t is only 2-byte aligned and a struct's tail is not padded);
//  * every word another process may change concurrently is a 32-bit
//    std::atomic that is always lock-free (m68k has no lock-free 64-bit
//    atomics; 32-bit CAS is `cas.l`).
//
// File map (every region page-aligned, in this order):
//   Header | RTPU table | express-mail rings | name registry |
//   local-memory windows (one arena per RTPU slot) | common memory (arena)
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <type_traits>

namespace chm::bp {

using A32 = std::atomic<std::uint32_t>;
static_assert(A32::is_always_lock_free, "backplane atomics must be lock-free");
static_assert(sizeof(A32) == 4);

inline constexpr std::uint32_t kMagic = 0x43484D42;         // "CHMB"
inline constexpr std::uint32_t kMagicSwapped = 0x424D4843;  // other byte order
// 3: remote semaphores 64-aligned, grant words apart; 4: a vacant slot's pid
// word names its generation, the recoverer is one word, STALE mail records;
// 5: 64-bit task ids in express-mail requests and replies (xmail.hpp), the
// 32-bit task words here carry their 31-bit short form (kernel::tid_short);
// 6: a message queue's header puts its lock, counters and level 0's list
// in one cache line (msgq/msgq.hpp).
inline constexpr std::uint32_t kLayoutVersion = 6;
inline constexpr std::uint32_t kPage = 4096;
inline constexpr std::uint32_t kMaxSlots = 32;   // attach masks are uint32_t
inline constexpr std::uint32_t kMinSlots = 2;
inline constexpr std::uint32_t kNameMax = 31;
inline constexpr std::uint64_t kMaxFileSize = 0xFFFFF000u;  // offsets are uint32_t

// ------------------------------------------------------------ the robust lock
//
// A lock word holds an owner token: 0 = free, else the holder's RTPU slot
// and that slot's generation (a slot's generation grows on every join, so a
// token never names a later occupant of the slot). Bit 23 marks a token
// used by the process recovering that slot (see rtpu.hpp).
//   token = (slot + 1) << 24 | recovery << 23 | (generation & 0x7FFFFF)
struct Lock {
    A32 token;        // owner token, 0 = free
    A32 owner_task;   // task id on that RTPU in 31 bits (kernel::tid_short), or 0x80000000 | Linux tid
    A32 dirty;        // 1 while the holder changes the protected structure
    std::uint32_t reserved;
};

inline constexpr std::uint32_t kTokenRecovery = 1u << 23;
inline constexpr std::uint32_t kGenMask = 0x7FFFFF;
constexpr std::uint32_t make_token(std::uint32_t slot, std::uint32_t gen, bool recovery = false) {
    return ((slot + 1) << 24) | (recovery ? kTokenRecovery : 0) | (gen & kGenMask);
}
constexpr std::uint32_t token_slot(std::uint32_t t) { return (t >> 24) - 1; }
constexpr std::uint32_t token_gen(std::uint32_t t) { return t & kGenMask; }
constexpr bool token_recovery(std::uint32_t t) { return (t & kTokenRecovery) != 0; }

// ------------------------------------------------------------------ header

enum RegionId : std::uint32_t {
    kRegionTable = 0, kRegionRings, kRegionRegistry, kRegionLocals, kRegionCommon, kRegionCount
};
inline constexpr const char* kRegionNames[kRegionCount] = {
    "rtpu_table", "rings", "registry", "locals", "common"};

struct Region {
    std::uint32_t offset;
    std::uint32_t size;
};

struct Geometry {
    std::uint32_t rtpu_slots;         // slot 0: host server; 1..: RTPUs and hosts
    std::uint32_t ring_records;       // express-mail records per RTPU ring
    std::uint32_t ring_record_size;   // bytes per record (multiple of 16)
    std::uint32_t local_window_size;  // bytes per RTPU window (multiple of kPage)
    std::uint32_t common_size;        // bytes of common memory (multiple of kPage)
    std::uint32_t registry_capacity;  // name registry entries
};

inline constexpr unsigned kExtGroupFlag = 0;
inline constexpr unsigned kExtGroupId = 1;
inline constexpr std::uint32_t kGroupMarker = 0x47525550;  // "GRUP"

struct Header {
    std::uint32_t magic;          // kMagic (kMagicSwapped: other byte order)
    std::uint32_t version;        // kLayoutVersion
    std::uint32_t header_size;    // sizeof(Header)
    std::uint32_t file_size;      // must equal the file's size
    std::uint64_t created_ns;     // CLOCK_REALTIME at creation
    Geometry geo;
    std::uint32_t table_entry_size;     // sizeof(RtpuEntry)
    std::uint32_t registry_entry_size;  // sizeof(RegistryEntry)
    Region regions[kRegionCount];
    std::uint32_t ring_stride;    // bytes per RTPU ring (RingHeader + records, page-rounded)
    std::uint32_t creator_pid;
    Lock registry_lock;           // guards the registry (and orders arena use)
    A32 recoveries;               // slots recovered after a death, in all
    A32 last_recovery_ms;         // monotonic ms when the last recovery ended
    // Reserved for later subsystems (state-variable table, console...):
    // zero at creation; each user documents its word here when it claims it.
    // ext[0] = kGroupMarker and ext[1] = gid: created for that group (mode
    // 0660), so group members may attach (trust.cpp).
    std::uint32_t ext[16];
    std::uint32_t reserved[8];
};

// ---------------------------------------------------------------- RTPU table

enum class SlotState : std::uint32_t { Free = 0, Joining, Running, Leaving, Dead, Recovering };
enum class SlotKind : std::uint32_t { None = 0, Rtpu = 1, Host = 2 };
inline constexpr std::uint32_t kStateCount = 6;

// status = generation << 8 | state: one word, so "slot n with generation g
// is RUNNING" is tested and changed by one compare-and-swap.
constexpr std::uint32_t make_status(std::uint32_t gen, SlotState s) {
    return (gen << 8) | static_cast<std::uint32_t>(s);
}
constexpr SlotState status_state(std::uint32_t st) { return static_cast<SlotState>(st & 0xFF); }
constexpr std::uint32_t status_gen(std::uint32_t st) { return st >> 8; }

// The pid word. A process that holds the slot is named by its pid (always
// < 2^22 on Linux); a vacant slot (FREE or DEAD with generation g, or
// JOINING g + 1 before the joiner named itself) holds vacant_pid(g). A
// joiner names itself by one CAS from the value it saw before its status
// CAS; a judge gives up a JOINING (g + 1) joiner that never named itself by
// the CAS of that value to vacant_pid(g + 1). Because the vacancy names the
// generation, a value never comes back once a generation ended, so a
// stalled joiner's naming CAS can never land in a later generation.
inline constexpr std::uint32_t kPidLimit = 1u << 22;  // PID_MAX_LIMIT
inline constexpr std::uint32_t kPidVacant = 0x80000000u;
constexpr std::uint32_t vacant_pid(std::uint32_t gen) { return kPidVacant | (gen & 0xFFFFFF); }
constexpr bool pid_named(std::uint32_t p) { return p != 0 && p < kPidLimit; }

// The recoverer word: who recovers a slot, pid | (start time & 0x3FF) << 22,
// 0 = nobody. One word, so claiming a recovery (CAS from 0) or taking over
// from a dead recoverer (CAS from its word) names the new recoverer in the
// same indivisible step: two recoverers can never both think they won.
inline constexpr std::uint32_t kRecovererStartBits = 10;
constexpr std::uint32_t recoverer_word(std::uint32_t pid, std::uint64_t start) {
    return (pid & (kPidLimit - 1)) | std::uint32_t(start & ((1u << kRecovererStartBits) - 1)) << 22;
}
constexpr std::uint32_t recoverer_pid_of(std::uint32_t w) { return w & (kPidLimit - 1); }

// A 64-bit word of the file that judges read while a joiner or a
// recoverer writes it: every access one relaxed atomic load or store, so
// nobody reads half of one (a plain move on x86-64 and aarch64; on m68k a
// libatomic call).
struct Word64 {
    std::uint64_t v;
    std::uint64_t load() const { return __atomic_load_n(&v, __ATOMIC_RELAXED); }
    void store(std::uint64_t x) { __atomic_store_n(&v, x, __ATOMIC_RELAXED); }
};

struct RtpuEntry {
    A32 status;              // generation << 8 | SlotState
    A32 kind;                // SlotKind
    A32 pid;                 // owning process, or vacant_pid(generation) (above)
    A32 tid;                 // its kernel thread: target of a directed signal
    Word64 pid_start;        // field 22 of /proc/<pid>/stat: detects pid reuse (0: unknown)
    A32 heartbeat_ms;        // monotonic ms, bumped by the owner's monitor thread
    A32 mailbox;             // futex word of the RTPU's mailbox interrupt (kernel issue)
    A32 pending;             // pending mailbox events, one bit per source (kernel issue)
    A32 idle;                // 1 while the RTPU sleeps on its mailbox futex
    A32 urgency;             // urgency of the task it runs now (port::RingFor), 0: lowest
    A32 poll_ns;             // poll this long before sleeping on the mailbox (0: never)
    A32 recoverer;           // recoverer_word of the process recovering it, 0: none
    std::uint32_t reserved0; // (layout 3: the recoverer's start time)
    A32 joined_ms;           // monotonic ms of the join
    A32 running;             // id of the task it runs now (port::RingFor), 0: none
    char name[kNameMax + 1];
    std::uint32_t reserved[8];
};

// ----------------------------------------------------- express-mail rings
//
// Reserved here, defined by the express-mail subsystem: per slot, a
// RingHeader then ring_records records of ring_record_size bytes. Creation
// fills capacity and record_size and zeroes the rest.
struct RingHeader {
    std::uint32_t capacity;
    std::uint32_t record_size;
    A32 head;
    A32 tail;
    Lock lock;
    std::uint32_t reserved[8];
};

// ------------------------------------------------------------ name registry

enum class EntryState : std::uint32_t { Free = 0, Live = 1, Destroying = 2 };

// Object kinds. Each kind may register a recovery callback (recovery.hpp).
enum ObjectKind : std::uint32_t {
    kKindNone = 0,
    kKindShm = 1,        // global shared memory segment (src/ipc/shm)
    kKindRemoteSem = 2,  // remote semaphores (src/ipc/rsem)
    kKindMsgQueue = 3,   // message queues (src/ipc/msgq)
    kKindStateVars = 4,  // the global state-variable table (src/ipc/svar)
    kKindMax = 32
};

inline constexpr std::uint32_t kWhereCommon = 0xFFFFFFFFu;

// Changed only under Header::registry_lock. `seq` is odd while an entry
// changes, so lookups may read committed entries without the lock.
struct RegistryEntry {
    A32 seq;
    A32 state;                 // EntryState
    A32 kind;                  // ObjectKind
    A32 offset;                // payload, from the file base (0 = none)
    A32 size;                  // payload bytes
    A32 where;                 // kWhereCommon or the RTPU slot whose window holds it
    A32 owner;                 // token of the creator
    A32 attached;              // bit s: slot s has it attached
    A32 name_words[8];         // NUL-terminated name, read word by word
    std::uint32_t reserved[8];
};

// ---------------------------------------------------------------- arenas
//
// Each local window and the common region is one arena: an ArenaHeader,
// then a chain of blocks that exactly fills it. A block is a 16-byte
// BlockHeader and its payload; free blocks are also on a doubly linked free
// list kept in their first payload words. Every step that changes the chain
// is one aligned 32-bit store, so a holder that dies mid-change leaves a
// chain the recovery can walk and rebuild (arena.hpp).
struct ArenaHeader {
    Lock lock;
    std::uint32_t magic;       // kArenaMagic
    std::uint32_t self;        // this header's offset (sanity)
    std::uint32_t size;        // bytes, header included
    A32 free_head;             // first free block's offset, 0 = none
    A32 used_bytes;            // bytes in used blocks, headers included
    A32 broken;                // 1: damaged beyond repair; calls fail
    A32 blocks;                // number of blocks in the chain
    std::uint32_t reserved[5];
};
inline constexpr std::uint32_t kArenaMagic = 0x4152454E;  // "AREN"

struct BlockHeader {
    A32 size_flags;            // block bytes (multiple of 16) | kUsed
    A32 prev_size;             // bytes of the physically previous block, 0 first
    A32 owner;                 // used: token of the allocating slot until committed (0)
    A32 tag;                   // offset ^ kBlockTagXor: catches stray headers
};
inline constexpr std::uint32_t kUsed = 1;
inline constexpr std::uint32_t kBlockTagXor = 0xB10C5EED;
inline constexpr std::uint32_t kBlockAlign = 16;
inline constexpr std::uint32_t kMinBlock = 32;  // header + two free-list links

// ------------------------------------------------------------ compile checks

template <class T>
constexpr bool kShared = std::is_standard_layout_v<T> && std::is_trivially_destructible_v<T>;

static_assert(kShared<Lock> && sizeof(Lock) == 16);
static_assert(kShared<Header> && sizeof(Header) == 224);
static_assert(offsetof(Header, created_ns) == 16 && offsetof(Header, geo) == 24);
static_assert(offsetof(Header, regions) == 56 && offsetof(Header, registry_lock) == 104);
static_assert(offsetof(Header, ext) == 128);
static_assert(kShared<RtpuEntry> && sizeof(RtpuEntry) == 128);
static_assert(offsetof(RtpuEntry, pid_start) == 16 && offsetof(RtpuEntry, name) == 64);
static_assert(kShared<RingHeader> && sizeof(RingHeader) == 64);
static_assert(kShared<RegistryEntry> && sizeof(RegistryEntry) == 96);
static_assert(offsetof(RegistryEntry, name_words) == 32);
static_assert(kShared<ArenaHeader> && sizeof(ArenaHeader) == 64);
static_assert(kShared<BlockHeader> && sizeof(BlockHeader) == 16);

}  // namespace chm::bp
