// The backplane's internal C++ interface: a process's view of the mapped
// file, its one attachment, the robust lock, the name registry, the arenas
// and death recovery. Other IPC subsystems (express mail, remote
// semaphores, message queues) build on this header; the public C API is
// include/chimera/bp.h, shm.h and spin.h.
//
// Lock order (never take an earlier one while holding a later one):
//   registry lock -> object locks (a subsystem's own) -> arena locks.
#pragma once

#include <cerrno>
#include <cstddef>
#include <cstdint>

#include <sys/stat.h>

#include "ipc/backplane/layout.hpp"

namespace chm::bp {

// ------------------------------------------------------------------ views

// The part of a validated header every lookup needs, as plain values.
struct Layout {
    Geometry geo{};
    Region regions[kRegionCount]{};
    std::uint32_t ring_stride = 0;
};
inline Layout layout_of(const Header& h) {
    Layout l;
    l.geo = h.geo;
    for (unsigned r = 0; r < kRegionCount; ++r) l.regions[r] = h.regions[r];
    l.ring_stride = h.ring_stride;
    return l;
}

// One process's mapping of a backplane file. Offsets are resolved here and
// nowhere else ("automatic address resolution"). `layout` is the header as
// map_file validated it, copied into process memory: every table index and
// region offset comes from it, so a header changed in the file after the
// open (another process's stray store, a corrupted file) cannot move a
// lookup outside the map.
struct View {
    char* base = nullptr;
    std::uint32_t size = 0;
    Layout layout{};

    Header* hdr() const { return reinterpret_cast<Header*>(base); }
    const Geometry& geo() const { return layout.geo; }
    template <class T>
    T* at(std::uint32_t off) const { return reinterpret_cast<T*>(base + off); }
    std::uint32_t off_of(const void* p) const {
        return static_cast<std::uint32_t>(static_cast<const char*>(p) - base);
    }
    bool contains(std::uint32_t off, std::uint32_t len) const {
        return off <= size && len <= size - off;
    }
    std::uint32_t slots() const { return layout.geo.rtpu_slots; }
    RtpuEntry* rtpu(std::uint32_t slot) const {
        return at<RtpuEntry>(layout.regions[kRegionTable].offset) + slot;
    }
    RegistryEntry* entry(std::uint32_t i) const {
        return at<RegistryEntry>(layout.regions[kRegionRegistry].offset) + i;
    }
    RingHeader* ring(std::uint32_t slot) const {
        return at<RingHeader>(layout.regions[kRegionRings].offset + slot * layout.ring_stride);
    }
    ArenaHeader* common_arena() const { return at<ArenaHeader>(layout.regions[kRegionCommon].offset); }
    ArenaHeader* local_arena(std::uint32_t slot) const {
        return at<ArenaHeader>(layout.regions[kRegionLocals].offset + slot * layout.geo.local_window_size);
    }
    // kWhereCommon or a slot number; nullptr when out of range.
    ArenaHeader* arena_for(std::uint32_t where) const {
        if (where == kWhereCommon) return common_arena();
        return where < slots() ? local_arena(where) : nullptr;
    }
    // The bytes an arena spans, [off, off + size), from the local layout.
    std::uint32_t arena_offset(std::uint32_t where) const {
        return where == kWhereCommon ? layout.regions[kRegionCommon].offset
                                     : layout.regions[kRegionLocals].offset + where * layout.geo.local_window_size;
    }
    std::uint32_t arena_size(std::uint32_t where) const {
        return where == kWhereCommon ? layout.geo.common_size : layout.geo.local_window_size;
    }
};

// The process's one attachment (chm_bp_join / chm_bp_attach_host).
struct Attachment : View {
    int fd = -1;
    std::uint32_t slot = 0;
    std::uint32_t gen = 0;
    std::uint32_t token = 0;
    SlotKind kind = SlotKind::None;
    std::uint32_t* local_refs = nullptr;  // per registry entry: attaches by this process
    // Per registry entry: what this process validated when it opened the
    // object (offset 0: not open here). A data path resolves a handle
    // through it, so it indexes the object with values no other process
    // can change (a message queue keeps its geometry in `words`).
    struct OpenObject {
        std::uint32_t offset, kind;
        std::uint32_t words[8];
    };
    OpenObject* objects = nullptr;
    char path[4096] = {};
};

// The attachment, or nullptr when this process is not attached. Other IPC
// subsystems use this; it stays valid until chm_bp_leave.
Attachment* current();
// current(), or nullptr with chm_bp_last_error() saying "<fn>: not attached
// to a backplane (chm_bp_join / chm_bp_attach_host first)" (no "<fn>: "
// when fn is nullptr). The public calls' first step (shm, msgq, svar).
Attachment* need_attachment(const char* fn = nullptr);
// registry_lock(*a, a->token), with chm_bp_last_error() set, prefixed as
// above, when a live holder kept it past the bound.
int lock_registry(Attachment* a, const char* fn = nullptr);
// How many attachments this process has made: process memory tied to one
// attachment (a segment's address) is stale when this has moved on.
std::uint32_t attach_count();

// -------------------------------------------------------------- the file

// The status of a shared structure that fails validation (a corrupt
// file or object: a field out of range, an index outside its table, a
// region that does not fit): -EBADMSG, as for a bad file header, with
// chm_bp_last_error() naming the object and the field. Never a crash.
inline constexpr int kCorrupt = -EBADMSG;
// Write the field's description into `why` (n bytes) and return kCorrupt.
int corrupt(char* why, std::size_t n, const char* fmt, ...) __attribute__((format(printf, 3, 4)));

// Why an operation failed, for chm_bp_last_error() (thread-local).
void set_error(const char* fmt, ...) __attribute__((format(printf, 1, 2)));
// `*path`, or when it is NULL the default backplane path written into buf
// (n bytes) and put in *path. 0, or -ENAMETOOLONG with set_error saying so.
int path_or_default(const char** path, char* buf, std::size_t n);

// Check a header against the file's size before anything is trusted.
// Returns 0 or -EBADMSG with `why` naming the field.
int validate_header(const Header& h, std::uint64_t file_size, char* why, std::size_t n);

// Validation beyond the header (validate.cpp). Each returns 0 or kCorrupt
// with `why` naming the structure and field.
// At attach: slot states and kinds, ring geometry, arena headers and every
// committed registry entry's payload (inside its arena, no 32-bit wrap,
// an allocated block): only what no live process changes mid-operation.
int validate_structure(const View& v, char* why, std::size_t n);
// Right after a join took `token` (a generation nobody had before): no
// lock of the backplane's own may name it. One that does can only be
// corrupt, and it would look held by a live process for ever (a recovery
// waiting for the registry lock would never end).
int validate_fresh_token(const View& v, std::uint32_t token, char* why, std::size_t n);
// At an object's open: entry `index`'s payload as above and at least
// `min_size` bytes; *off and *size receive the checked values.
int entry_payload(const View& v, std::uint32_t index, std::uint32_t min_size, std::uint32_t* off,
                  std::uint32_t* size, char* why, std::size_t n);
// A whole file at rest (chm_bp_validate, chimera start and status):
// validate_structure, every arena nobody holds, every live object by its
// kind's validator. Read-only.
int validate_file(const View& v, char* why, std::size_t n);

// Open, validate and map a backplane file (read-write or read-only).
// Nothing is left mapped or open on error; `why` names the problem.
// `trust`: refuse a file this process must not attach (check_trust, and
// the default directory's check): every attach, chimera status/stop/rm;
// only the read-only checker (chimera-bpcheck) looks at any file.
int map_file(const char* path, bool writable, View* out, int* fd_out, char* why, std::size_t n,
             bool trust);

// trust.cpp. Whether a file (fstat'ed from the open descriptor) may be
// attached by this process: a regular file owned by the caller (or shared
// with the caller's group when made for it), no permission for others.
// `h` is its header (NULL when unread). 0, -EBADMSG or -EPERM with `why`.
int check_trust(const struct stat& st, const Header* h, char* why, std::size_t n);
// Before opening: a symlink (-ELOOP) or a non-regular file (-EBADMSG) at
// `path`, described for the message; 0 otherwise (the fstat decides).
int describe_untrusted_path(const char* path, char* why, std::size_t n);
// When `path` lies in the default directory: chm_bp_check_dir on it.
int check_default_dir_of(const char* path, bool create);
void unmap(View* v);

// Geometry -> file layout. Returns false (and `why`) when out of range.
bool plan_layout(const Geometry& g, Header* h, char* why, std::size_t n);

// ------------------------------------------------------ processes and time

std::uint32_t mono_ms();
// Field 22 of /proc/<pid>/stat (start time in clock ticks since boot), or 0
// when there is no such process or it is a zombie.
std::uint64_t proc_start_time(int pid);
// Is `pid` alive and (when start != 0) the process that started at `start`?
bool proc_alive(int pid, std::uint64_t start);
std::uint64_t self_start_time();
// This process as a recoverer (layout.hpp, recoverer_word), and whether
// the process a recoverer word names is alive (0 names nobody: false).
std::uint32_t self_recoverer_word();
bool recoverer_alive(std::uint32_t w);
// Give the CPU away for about `ns`: inside a Chimera task, to the other
// tasks of its RTPU (chm_task_pause_until); elsewhere nanosleep.
void relinquish(std::uint64_t ns);
// What a lock records as its holder's task: the Chimera task id, or
// 0x80000000 | Linux thread id outside a task.
std::uint32_t task_word();
// In a forked child (the forking thread's cached thread id is stale).
void proc_after_fork_child();

// ------------------------------------------------------ signalling members

// member.cpp: the only way to signal another process of the backplane.
// The slot's pid (and thread id) are checked with the kernel first: alive
// with the recorded start time, a user the backplane trusts, this file
// mapped; a thread of it that catches the wake signal. A claim that fails
// is reported (last error and stderr: slot, field, value) and not
// signalled. Thread verdicts are cached per slot until its status, pid or
// tid word changes, so a wake-up pays nothing after the first.
enum class MemberTarget { KernelThread, Process };
// `status`: for Process, the slot's status the caller saw (-ESRCH when it
// changed since: the member left). 0, -EPERM (refused), -ESRCH (no
// process, or no kernel thread published), -ENOTCONN, -EINVAL.
int signal_member(std::uint32_t slot, MemberTarget target, int sig, std::uint32_t status = 0);
// Drop every cached verdict (attach, leave, a forked child).
void member_forget();
// Open, read-only, the file that descriptor `remote_fd` of the member in
// `slot` has open (through /proc/<pid>/fd: a new open file description),
// after the same checks as a signal. 0 and *out, -EPERM (refused and
// reported), -ESRCH (gone), -ENOTCONN, -EINVAL, or the open's -errno.
int open_member_file(std::uint32_t slot, int remote_fd, int* out);

// --------------------------------------------------------- the robust lock

// Does `token` name a live holder? Cheap: the RTPU table says so (slot in
// JOINING, RUNNING or LEAVING with that generation; a recovery token:
// slot RECOVERING). Deep: also asks the kernel whether the process lives.
bool token_alive(const View& v, std::uint32_t token, bool deep);

// A bound on every lock_acquire of this thread while it lives, on top of
// each call's own timeout: a budget from now, and a flag that, once set
// (by another thread), ends the thread's lock waits within one polling
// interval. Scopes nest (the inner one is never looser). lock_acquire
// answers a wait the scope ended with -ETIMEDOUT. Used where a wait must
// not outlast its caller's bound: the monitor thread (stopped by
// chm_bp_leave and fork), a recovery attempt, chm_bp_leave itself.
struct WaitBound {
    WaitBound(std::uint64_t budget_ns, const std::atomic<bool>* cancel = nullptr);
    ~WaitBound();
    WaitBound(const WaitBound&) = delete;
    WaitBound& operator=(const WaitBound&) = delete;
    // Has this thread's innermost scope run out (or been cancelled)?
    static bool over();
    std::uint64_t deadline_ns;  // port::now_ns()
    const std::atomic<bool>* cancel;
    const WaitBound* outer;
};

// Acquire `l` for `me` (a token). Tests the lock continuously for the
// first `poll_ns`, then once every `poll_ns`, giving the CPU away between
// tests (relinquish). A holder that is dead is robbed: the lock passes to
// `me` by compare-and-swap from exactly that token.
// Returns 0; -EOWNERDEAD: acquired, the previous holder died (check
// l->dirty and repair); -ETIMEDOUT after `timeout_ns` (UINT64_MAX: none),
// when the thread's WaitBound ends, or after kTryLockNs with the interrupt
// mask held (masked_wait).
int lock_acquire(const View& v, Lock* l, std::uint32_t me, std::uint64_t poll_ns,
                 std::uint64_t timeout_ns);
// One attempt: 0, -EOWNERDEAD (robbed a dead holder) or -EBUSY.
int lock_try(const View& v, Lock* l, std::uint32_t me);
// For the calls that must not wait (the try calls): spins on the lock for
// at most `spin_ns` (kTryLockNs) and never gives the CPU away, then asks
// the kernel once whether the holder lives (a dead one is robbed). A live
// holder's critical section is a few hundred ns, so only a holder that
// stalls inside one (stopped, preempted, descheduled) makes it fail.
// 0, -EOWNERDEAD (robbed: check l->dirty and repair) or -EBUSY.
int lock_acquire_brief(const View& v, Lock* l, std::uint32_t me, std::uint64_t spin_ns);
// Is the caller on an RTPU's kernel thread with the interrupt mask held
// (an interrupt handler, a chm_irq_lock section)? Its lock waits are cut
// to kTryLockNs, spinning: nothing else of the RTPU runs meanwhile.
bool masked_wait();
// Who holds `l`, for an error text: "slot 3 (task 65537)", "slot 1
// (thread 4242)" or "nobody". snprintf's return.
int lock_holder(const Lock* l, char* out, std::size_t n);
// lock_acquire for an object's recovery under recovery token `rt`: a lock
// that `rt` holds already is ours (a recoverer that died mid-recovery held
// it, and this process took its work over under the same token), returned
// as -EOWNERDEAD: check l->dirty and repair. Without this, the takeover
// waited for itself until the timeout and left the dead slot's waiters.
int lock_acquire_recovery(const View& v, Lock* l, std::uint32_t rt);
void lock_release(Lock* l);
// The token of a lock whose holder task ended inside a call with it dirty
// (lock.cpp, release_abandoned): its slot field names no slot, so every
// waiter finds it dead and robs it at once.
inline constexpr std::uint32_t kOrphanToken = 0xFF000000u;
// Set before changing the structure a lock guards, clear after.
void lock_mark_dirty(Lock* l);
void lock_clear_dirty(Lock* l);
// Internal locks wait at most this long for a live holder (calls that may
// block: open, create, P, send, receive, ...; docs/backplane.md, "Every
// wait and its bound").
inline constexpr std::uint64_t kInternalTimeoutNs = 5'000'000'000ull;
// A try call waits at most this long for an internal lock, spinning.
inline constexpr std::uint64_t kTryLockNs = 20'000;
// A V (chm_rsem_v) waits at most this long for its semaphore's lock.
inline constexpr std::uint64_t kReleaseLockNs = 10'000'000;
inline constexpr std::uint64_t kInternalPollNs = 20'000;

// ---------------------------------------------------------------- arenas

void arena_init(const View& v, std::uint32_t off, std::uint32_t size);
// With the lock held: is the arena one its operations can walk safely?
// Header where the layout puts it, a chain of blocks that exactly fills
// it (sizes, tags, prev sizes), a free list of its free blocks without a
// cycle. 0, or kCorrupt with `why` naming the arena and field. arena_lock
// runs it, so alloc and free only ever follow checked offsets.
int arena_validate_locked(const View& v, const ArenaHeader* a, char* why, std::size_t n);
// Lock an arena (repairing it if its last holder died mid-change) and
// validate it (arena_validate_locked). 0, -ETIMEDOUT, -ENOTRECOVERABLE
// (broken: its chain could not be walked), kCorrupt (set_error says why;
// the lock is not held then).
int arena_lock(const View& v, ArenaHeader* a, std::uint32_t me);
void arena_unlock(ArenaHeader* a);
// With the arena lock held: a payload offset (16-aligned) or 0 (no space).
// The block is uncommitted (owner = `owner`) until arena_commit.
std::uint32_t arena_alloc_locked(const View& v, ArenaHeader* a, std::uint32_t size,
                                 std::uint32_t owner);
void arena_commit(const View& v, std::uint32_t payload);
// 0, or -EINVAL when `payload` is not a used block of this arena.
int arena_free_locked(const View& v, ArenaHeader* a, std::uint32_t payload);
// Is `payload` a used block of `a` with at least `size` bytes?
bool arena_block_used(const View& v, const ArenaHeader* a, std::uint32_t payload,
                      std::uint32_t size);
// Walk the chain, fix prev sizes, merge neighbouring free blocks, rebuild
// the free list and counters. False (and the arena marked broken) when the
// chain itself is damaged.
bool arena_rebuild_locked(const View& v, ArenaHeader* a);
// Free every used block still owned by an allocation that was never
// committed (only possible for a holder of the registry lock who died).
void arena_sweep_uncommitted_locked(const View& v, ArenaHeader* a);
std::uint32_t arena_free_bytes(const View& v, const ArenaHeader* a);

// Report sink for the strict checks (bpcheck, tests).
struct Report {
    void (*emit)(void* ctx, const char* line) = nullptr;
    void* ctx = nullptr;
    unsigned problems = 0;
    void problem(const char* fmt, ...) __attribute__((format(printf, 2, 3)));
};
// A lock's part of the strict checks: held by a dead owner, or free but
// dirty, is a problem named `what`.
void check_lock(const View& v, const Lock& l, const char* what, Report& r);

// Strict consistency check of one arena (read-only). `name` prefixes lines.
void arena_check(const View& v, const ArenaHeader* a, std::uint32_t off, std::uint32_t size,
                 const char* name, Report& r);

// What check_backplane counted.
struct Summary {
    std::uint32_t rtpus = 0, hosts = 0, dead = 0, objects = 0, destroying = 0;
    std::uint64_t common_used = 0, common_size = 0, local_used = 0, local_size = 0;
};
// Verify every structure of a mapped file (read-only; header already
// validated by map_file): the RTPU table and its processes, every lock
// (held by a dead owner? left dirty?), the rings, the registry and every
// arena. One Report line per problem. On a live system a structure in the
// middle of a change may be reported; a quiescent file must check clean.
void check_backplane(const View& v, Report& r, Summary* sum);

// -------------------------------------------------------- name registry

// Lock the registry for `me`, repairing it when its last holder died
// mid-change. 0, -ETIMEDOUT or -ENOTRECOVERABLE.
int registry_lock(const View& v, std::uint32_t me);
void registry_unlock(const View& v);
// With the registry lock held: the index of the live entry called `name`
// (any kind when kind == kKindNone), or -ENOENT.
int registry_find_locked(const View& v, const char* name, std::uint32_t kind);
// The index of the entry whose payload starts at `offset`, or -ENOENT.
int registry_find_offset_locked(const View& v, std::uint32_t offset);

// A committed entry's contents, read without the lock.
struct EntryInfo {
    std::uint32_t index, kind, offset, size, where, owner;
};
// Lock-free lookup of a live entry: 0 or -ENOENT.
int registry_lookup(const View& v, const char* name, std::uint32_t kind, EntryInfo* out);

// Create an object: reserve an entry, allocate `size` bytes in `where`
// (kWhereCommon or a slot's window), commit, and mark it attached by slot
// `attach_slot`. The caller holds the registry lock (so it can initialise
// the object before anyone can find it... the entry is live on return).
// 0; -EEXIST, -ENOSPC (registry full), -ENOMEM (window full), -EINVAL,
// -ENOTRECOVERABLE (arena broken), -ETIMEDOUT.
int registry_create_locked(const View& v, std::uint32_t me, std::uint32_t kind, const char* name,
                           std::uint32_t size, std::uint32_t where, std::uint32_t attach_slot,
                           EntryInfo* out);
// Remove the name now; the memory goes when no slot has it attached.
void registry_destroy_locked(const View& v, std::uint32_t index, std::uint32_t me);
// Clear slot's attach bit; frees a destroyed entry nobody holds.
void registry_detach_locked(const View& v, std::uint32_t index, std::uint32_t slot,
                            std::uint32_t me);
// This process opens entry `index` once more (registry lock held): its
// slot's attach bit is set and the process's reference counted.
void registry_ref_locked(Attachment& a, std::uint32_t index);
// This process closes the entry of `kind` whose payload starts at `offset`
// once (registry lock held); its last reference detaches the slot.
// 0, or -EINVAL when the process holds no such entry open.
int registry_unref_locked(Attachment& a, std::uint32_t offset, std::uint32_t kind);
// The repair run when the registry lock was robbed from a dead holder
// mid-change: finish or undo entries left half-changed and free
// allocations never committed. Also run by every recovery.
void registry_repair_locked(const View& v, std::uint32_t me);
void read_name(const RegistryEntry* e, char out[kNameMax + 1]);
bool valid_name(const char* name, std::size_t* len);

// -------------------------------------------------------------- recovery

// Called for every live or destroying registry entry of its kind when slot
// `dead_slot` (generation `dead_gen`) died, with the registry lock held by
// `recovery_token`. It removes the dead RTPU's waiters, robs the dead
// RTPU's locks of the object (lock_acquire with recovery_token robs them),
// and repairs the object or marks it broken.
using RecoverFn = void (*)(const View& v, std::uint32_t entry_index, std::uint32_t dead_slot,
                           std::uint32_t dead_gen, std::uint32_t recovery_token);
// Register the callback of one kind in this process (later registrations
// replace earlier). 0 or -EINVAL. Subsystems that must always be recovered
// also add a line to kBuiltinRecovery in recovery.cpp, so any survivor
// recovers them whether or not it used that subsystem.
int register_recovery(std::uint32_t kind, RecoverFn fn);

}  // namespace chm::bp
namespace chm::ipc {
// Built-in recovery functions of the subsystems (listed in recovery.cpp).
void rsem_recover(const bp::View& v, std::uint32_t entry_index, std::uint32_t dead_slot,
                  std::uint32_t dead_gen, std::uint32_t recovery_token);
namespace msgq {
void recover(const bp::View& v, std::uint32_t entry_index, std::uint32_t dead_slot,
             std::uint32_t dead_gen, std::uint32_t recovery_token);
}
// Their strict read-only checks of one live object at `off` (`size` bytes
// allocated), called by check_backplane for each registry entry of their
// kind: one Report line per problem, prefixed with `name`. An object whose
// lock a live process holds may be mid-change and is skipped.
void rsem_check(const bp::View& v, std::uint32_t off, std::uint32_t size, const char* name, bp::Report& r);
namespace msgq {
void check_entry(const bp::View& v, std::uint32_t off, std::uint32_t size, const char* name, bp::Report& r);
}
// Their validators of one live object at `off` (`size` bytes), read-only:
// what its open checks, for validate_file. 0 or bp::kCorrupt with `why`
// prefixed by `name`.
int rsem_validate(const bp::View& v, std::uint32_t off, std::uint32_t size, const char* name, char* why,
                  std::size_t n);
// The state-variable table (src/ipc/svar): all three hooks.
void svar_recover(const bp::View& v, std::uint32_t entry_index, std::uint32_t dead_slot,
                  std::uint32_t dead_gen, std::uint32_t recovery_token);
void svar_check(const bp::View& v, std::uint32_t off, std::uint32_t size, const char* name, bp::Report& r);
int svar_validate(const bp::View& v, std::uint32_t off, std::uint32_t size, const char* name, char* why,
                  std::size_t n);
namespace msgq {
int validate_entry(const bp::View& v, std::uint32_t off, std::uint32_t size, const char* name, char* why,
                   std::size_t n);
}
}  // namespace chm::ipc
namespace chm::bp {

// Recover slot `slot` of generation `gen` if its holder is dead and nobody
// else is recovering it: rob its locks, repair, run the per-kind callbacks,
// detach it everywhere, mark it DEAD. Returns true when this call did the
// recovery; false also while a live process holds the slot's recoverer
// word (callers retry). Safe to call from any number of processes at once.
bool recover_slot(const View& v, std::uint32_t slot, std::uint32_t gen);

// A graceful leave (chm_bp_leave, slot LEAVING, registry lock held by
// `token` = make_token(slot, gen)): the departing process withdraws every
// waiter record it still has, as its recovery would after a death. A task
// parked in a backplane wait when its RTPU stopped never returns from it,
// so nobody else would: each kind's callback drops the records (a grant
// they hold is passed on or given back) and the express-mail requests are
// given up. Locks the departing token still holds are adopted and repaired
// like a dead holder's (lock_acquire_recovery).
void withdraw_departing(const View& v, std::uint32_t slot, std::uint32_t gen, std::uint32_t token);

// Is the holder of slot `slot` (as of status `st`) dead? Deep check. A
// JOINING slot whose joiner has not named itself yet (pid word not a pid
// and not vacant_pid of its generation) is not dead: it must first be
// given up by joining_abandon, which the judges do only after the same
// words stayed for kConfirmMs.
bool slot_holder_dead(const View& v, std::uint32_t slot, std::uint32_t st);

// How long a JOINING slot's words must stay the same before a judge
// believes the joiner dead (take_slot, the monitor).
inline constexpr std::uint32_t kConfirmMs = 20;
// The same for a joiner that has not named itself: longer, as a live one
// stalled that long between two instructions is given up (it then starts
// over), and only a joiner killed in that window leaves such a slot.
inline constexpr std::uint32_t kUnnamedConfirmMs = 100;
// Slot `slot` was JOINING with status `st` and pid word `pid` kConfirmMs
// (kUnnamedConfirmMs when `pid` names no process) ago (pid read after st). True when both are still so and the joiner is
// dead: named and gone, or never named and now given up by this call (CAS
// of `pid` to vacant_pid: its own naming CAS then fails, so it never
// writes into the slot again).
bool joining_abandon(const View& v, std::uint32_t slot, std::uint32_t st, std::uint32_t pid);

// The monitor thread of the current attachment.
int monitor_start(Attachment* a);
// Stops the thread and joins it. `before_fork`: also waits (at most
// kThreadGoneNs) until the OS no longer has the thread. Under qemu-user a
// guest's pthread_join returns when the exiting thread clears its tid
// word, before that thread's host side has freed its state; a fork in
// that window copied the emulator's allocator lock held, and the child
// hung in its first translation (tests/ipc/test_ipc_bounds.cpp, about 1
// run in 16 under load).
void monitor_stop(bool before_fork = false);
// In a forked child: the thread does not exist there; drop its state.
void monitor_forget_after_fork();

}  // namespace chm::bp
