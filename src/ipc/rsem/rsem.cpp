// Remote semaphores (chimera/rsem.h): a count and a table of waiter
// records in backplane memory under one robust lock. A waiter parks on its
// record's grant word (ipc/wake); V picks the most urgent record, stores
// the grant under the lock and wakes it after. Recovery removes a dead
// slot's records and passes on a grant it never took.
#include <cerrno>
#include <cstdarg>
#include <climits>
#include <cstddef>
#include <cstdint>
#include <cstdio>

#include "chimera/bp.h"
#include "chimera/rsem.h"
#include "chimera/shm.h"
#include "chimera/task.h"
#include "ipc/backplane/backplane.hpp"
#include "ipc/backplane/stop_point.hpp"
#include "ipc/wake/wake.hpp"
#include "ipc/err/report.hpp"
#include "kernel/sync/remote_wait.hpp"
#include "kernel/task/holds.hpp"

using namespace chm::bp;

struct chm_rsem;  // the handle is the shared object's address

namespace chm::ipc {
namespace {

constexpr std::uint32_t kRsemMagic = 0x5253454d;  // "RSEM"
enum WaiterState : std::uint32_t { kFree = 0, kWaiting = 1, kGranted = 2 };

// Six words, so that the lock, the counters and record 0 fill one cache
// line: a V that takes the lock has the usual single waiter's record too.
struct Waiter {
    A32 state;
    A32 owner;    // make_token(slot, generation) of the waiting process
    A32 prio;     // task priority (higher first); host threads 0
    A32 seq;      // arrival, FIFO among equals
    A32 task;     // the parked task's id (WaiterId); 0: the futex
    A32 urgency;  // WaiterId::urgency
};

struct Rsem {
    Lock lock;
    A32 magic;
    A32 kind;
    A32 count;
    A32 nwaiting;
    A32 seq;
    A32 broken;
    Waiter w[CHM_RSEM_WAITERS];  // taken lowest index first
    // The word record i's owner waits on, alone in its cache line: a
    // granter's exchange then moves one line the waiter spins on, and
    // reading the records does not take it from the spinner first.
    struct GrantLine {
        A32 word;
        std::uint32_t pad[15];
    } grant[CHM_RSEM_WAITERS];
};
static_assert(std::is_standard_layout_v<Rsem>);
static_assert(offsetof(Rsem, w) + sizeof(Waiter) == 64, "lock, counters and record 0: one line");

// The backplane's allocator aligns to 16 bytes; a semaphore takes 48 more
// and starts at the first 64-byte boundary inside, the same in every
// process (mappings are page-aligned).
constexpr std::uint32_t kAllocSize = sizeof(Rsem) + 48;
Rsem* rsem_at(void* allocation) {
    const auto p = reinterpret_cast<std::uintptr_t>(allocation);
    return reinterpret_cast<Rsem*>((p + 63) & ~std::uintptr_t(63));
}

Rsem* from_handle(chm_rsem_t* h) {
    Attachment* a = current();
    if (!a || !h) return nullptr;
    const char* p = reinterpret_cast<const char*>(h);
    if (p < a->base || p + kAllocSize > a->base + a->size) return nullptr;
    Rsem* s = rsem_at(h);
    return s->magic.load(std::memory_order_relaxed) == kRsemMagic ? s : nullptr;
}


// A semaphore's words that open checks: its kind, a binary count of at
// most 1, every record's state and nwaiting against the records (V's
// scan stops after nwaiting waiting records, so it must not exceed them).
// The records themselves are a fixed array: nothing else indexes it.
int validate_sem(const Rsem* s, char* why, std::size_t n) {
    constexpr auto R = std::memory_order_relaxed;
    const std::uint32_t kind = s->kind.load(R);
    if (kind != CHM_SEM_BINARY && kind != CHM_SEM_COUNTING)
        return corrupt(why, n, "kind is %u, not binary or counting", kind);
    if (kind == CHM_SEM_BINARY && s->count.load(R) > 1) return corrupt(why, n, "count is %u in a binary semaphore", s->count.load(R));
    // Only a quiescent semaphore's nwaiting is exact: the scan counts when
    // the lock was free and nwaiting, count and seq unchanged from before
    // it to after it (a P or V landing during the scan otherwise reads as
    // corruption); else it is tried again, a few times, then not judged.
    // seq because a grant and a new waiter in between bring nwaiting back
    // to its value (seen under ThreadSanitizer's timing: "nwaiting is 1,
    // 0 records wait"); every waiter that enqueues moves seq.
    for (int attempt = 0; attempt < 8; ++attempt) {
        const std::uint32_t token = s->lock.token.load(std::memory_order_acquire);
        const std::uint32_t nwaiting = s->nwaiting.load(R), count = s->count.load(R), seq = s->seq.load(R);
        std::uint32_t waiting = 0;
        for (std::uint32_t i = 0; i < CHM_RSEM_WAITERS; ++i) {
            const std::uint32_t st = s->w[i].state.load(R);
            if (st > kGranted) return corrupt(why, n, "waiter %u: state %u is not FREE, WAITING or GRANTED", i, st);
            waiting += st == kWaiting;
        }
        std::atomic_thread_fence(std::memory_order_acquire);
        const bool stable = token == 0 && s->lock.token.load(R) == 0 && s->nwaiting.load(R) == nwaiting &&
                            s->count.load(R) == count && s->seq.load(R) == seq;
        if (!stable) continue;
        if (nwaiting != waiting) return corrupt(why, n, "nwaiting is %u, %u records wait", nwaiting, waiting);
        return 0;
    }
    return 0;
}

std::uint32_t* grant_of(Rsem* s, const Waiter* w) {
    return reinterpret_cast<std::uint32_t*>(&s->grant[w - s->w].word);
}
const std::uint32_t* grant_of(const Rsem* s, const Waiter* w) {
    return reinterpret_cast<const std::uint32_t*>(&s->grant[w - s->w].word);
}

std::uint32_t owner_slot(const Waiter* w) { return token_slot(w->owner.load()); }

WaiterId recorded(const Waiter* w) { return WaiterId{w->task.load(), w->urgency.load()}; }

// A record marked GRANTED whose grant word was never stored: its granter
// (a V, a withdrawal, a recovery) ended between give_locked's two stores.
// Only ever seen under a lock left dirty.
bool half_granted(const Rsem* s, const Waiter& w) {
    return w.state.load() == kGranted &&
           !chm::kernel::word_granted(__atomic_load_n(grant_of(s, &w), __ATOMIC_ACQUIRE));
}

int give_locked(Rsem* s, Waiter** woken);

// The repair after a holder died (or its task ended) between marking the
// lock dirty and clearing it. nwaiting is counted again; a grant left half
// done is finished: a live waiter gets its word and is woken now (under
// the lock: this is rare, and a granted waiter takes its unit without the
// lock), a dead or departed one's unit goes to the next waiter or the
// count.
void repair_locked(Rsem* s) {
    std::uint32_t n = 0, passed = 0;
    const Attachment* a = current();
    for (Waiter& w : s->w) {
        if (w.state.load() == kWaiting) ++n;
        if (!half_granted(s, w)) continue;
        if (a && token_alive(*a, w.owner.load(), false)) {
            if (!store_grant(grant_of(s, &w), 1)) wake_granted(grant_of(s, &w), owner_slot(&w), recorded(&w));
        } else {
            w.state.store(kFree);
            ++passed;
        }
    }
    s->nwaiting.store(n);
    if (s->kind.load() == CHM_SEM_BINARY && s->count.load() > 1) s->count.store(1);
    for (; passed; --passed) {  // the rest is consistent: a death in here loses only these units
        Waiter* w = nullptr;
        (void)give_locked(s, &w);
        if (w) wake_granted(grant_of(s, w), owner_slot(w), recorded(w));
    }
}

// How long a call waits for the semaphore's lock held by a live process
// (docs/backplane.md, "Every wait and its bound").
enum class LockWait {
    kBlocking,  // kInternalTimeoutNs (5 s), then -EDEADLK
    kTry,       // kTryLockNs (20 µs) spinning, then -EAGAIN: a try never waits
    kRelease,   // kReleaseLockNs (10 ms), then -EBUSY: a V is not held up for seconds
    kTimed,     // what is left of the call's timeout (< 5 s), then -ETIMEDOUT
};  // With the interrupt mask held, each is cut to kTryLockNs (masked_wait).

// The lock wait of a P with `limit`.
LockWait p_wait(const chm::ipc::WaitLimit& limit, std::uint64_t* budget) {
    bool own = false;
    *budget = limit.lock_budget(kInternalTimeoutNs, &own);
    if (limit.kind == chm::ipc::WaitLimit::kNoWait) return LockWait::kTry;
    return own ? LockWait::kTimed : LockWait::kBlocking;
}

int lock(Rsem* s, LockWait wait = LockWait::kBlocking, std::uint64_t budget = 0) {
    Attachment* a = current();
    const std::uint64_t bound = wait == LockWait::kRelease  ? kReleaseLockNs
                                : wait == LockWait::kTimed ? budget
                                                           : kInternalTimeoutNs;
    int r = wait == LockWait::kTry || bound == 0
                ? lock_acquire_brief(*a, &s->lock, a->token, kTryLockNs)
                : lock_acquire(*a, &s->lock, a->token, kInternalPollNs, bound);
    if (r == -EOWNERDEAD) {
        repair_locked(s);
        lock_clear_dirty(&s->lock);
        r = 0;
    }
    if (r == -ETIMEDOUT || r == -EBUSY) {
        char who[48];
        lock_holder(&s->lock, who, sizeof who);
        if (wait == LockWait::kTry) {
            set_error("remote semaphore: its lock is held by %s, a live process: a try call does not wait", who);
            return -EAGAIN;
        }
        // With the interrupt mask held every wait is a try's (masked_wait).
        const char* past = masked_wait() ? "20 us (interrupts masked)"
                           : wait == LockWait::kRelease ? "10 ms"
                           : wait == LockWait::kTimed   ? "the call's timeout"
                                                        : "5 s";
        if (wait == LockWait::kRelease) {
            set_error("remote semaphore: its lock was held by %s, a live process, past %s: the unit was not given",
                      who, past);
            return -EBUSY;
        }
        set_error("remote semaphore: its lock was held by %s, a live process, past %s", who, past);
        return wait == LockWait::kTimed ? -ETIMEDOUT : -EDEADLK;
    }
    if (r == 0 && s->broken.load()) {
        lock_release(&s->lock);
        set_error("remote semaphore: damaged by a process that died in it");
        return -ENOTRECOVERABLE;
    }
    return r;
}

void unlock(Rsem* s) { lock_release(&s->lock); }

// The most urgent waiting record, or nullptr. Lock held. A record whose
// process died or left (its token no longer live) is dropped on the way,
// as message queues do: its recovery has not run yet, and a unit granted
// to it would be lost with it.
Waiter* most_urgent_locked(Rsem* s) {
    Waiter* best = nullptr;
    const Attachment* a = current();
    std::uint32_t left = s->nwaiting.load();  // stop after the last waiting record
    for (Waiter& w : s->w) {
        if (!left) break;
        if (w.state.load() != kWaiting) continue;
        --left;
        if (a && !token_alive(*a, w.owner.load(), false)) {
            lock_mark_dirty(&s->lock);
            w.state.store(kFree);
            s->nwaiting.store(s->nwaiting.load() - 1);
            lock_clear_dirty(&s->lock);
            continue;
        }
        if (!best || w.prio.load() > best->prio.load() ||
            (w.prio.load() == best->prio.load() && int32_t(w.seq.load() - best->seq.load()) < 0))
            best = &w;
    }
    return best;
}

// Give one unit: to the most urgent waiter (returned when it must be woken
// after the unlock: not when its RTPU polls its word) or to the count.
// Lock held.
int give_locked(Rsem* s, Waiter** woken) {
    *woken = nullptr;
    if (Waiter* w = most_urgent_locked(s)) {
        constexpr auto R = std::memory_order_relaxed;
        lock_mark_dirty(&s->lock);
        s->nwaiting.store(s->nwaiting.load(R) - 1, R);
        // Before the grant (whose exchange releases it): the waiter frees
        // its record after seeing the grant, without the lock.
        w->state.store(kGranted, R);
        CHM_STOP_POINT("rsem.v.granted");  // mid-grant: GRANTED, its word not stored yet
        const bool watched = store_grant(grant_of(s, w), 1);
        lock_clear_dirty(&s->lock);
        if (!watched) *woken = w;
        return 0;
    }
    if (s->kind.load() == CHM_SEM_BINARY) {
        s->count.store(1);
        return 0;
    }
    if (s->count.load() == UINT32_MAX) return -EOVERFLOW;
    s->count.store(s->count.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);  // lock held: no RMW
    return 0;
}

// Unlock, then wake `woken` (give_locked's waiter, or nullptr): its slot
// and identity are read while the lock still keeps its record.
void unlock_and_wake(Rsem* s, Waiter* woken) {
    std::uint32_t slot = 0;
    WaiterId who;
    if (woken) {
        slot = owner_slot(woken);
        who = recorded(woken);
    }
    unlock(s);
    if (woken) wake_granted(grant_of(s, woken), slot, who);
}

// A task ended waiting in P (an abort or an exception in a handler run at
// the wait; kernel/task/holds.hpp) with record `p`, number `index` of its
// semaphore: withdrawn as a timed-out waiter's would be, and a unit
// granted to it and never taken goes to the next waiter or the count.
void withdraw_abandoned(void* p, std::uint32_t index) {
    Waiter* me = static_cast<Waiter*>(p);
    Rsem* s = reinterpret_cast<Rsem*>(reinterpret_cast<char*>(me - index) - offsetof(Rsem, w));
    const Attachment* a = current();
    if (!a || index >= CHM_RSEM_WAITERS || lock(s) != 0) return;
    Waiter* woken = nullptr;
    if (me->owner.load() == a->token) {
        const std::uint32_t st = me->state.load();
        lock_mark_dirty(&s->lock);
        if (st == kWaiting) s->nwaiting.store(s->nwaiting.load() - 1);
        me->state.store(kFree);
        lock_clear_dirty(&s->lock);
        if (st == kGranted) (void)give_locked(s, &woken);  // (marks the lock dirty itself)
    }
    unlock_and_wake(s, woken);
}

}  // namespace

// Recovery (with the registry lock held by `rt`): drop the dead slot's
// records; a grant it never took goes to the next waiter or the count.
// Listed in the backplane's built-in recovery table, so every survivor
// recovers remote semaphores whether or not it uses them.
void rsem_recover(const View& v, std::uint32_t index, std::uint32_t dead_slot, std::uint32_t dead_gen,
             std::uint32_t rt) {
    // The entry's offset is followed only once it is a block of its arena
    // big enough for a semaphore, and the semaphore only when it is sound.
    std::uint32_t off, size;
    char why[200];
    if (entry_payload(v, index, kAllocSize, &off, &size, why, sizeof why) != 0) return;
    Rsem* s = rsem_at(v.at<char>(off));
    if (s->magic.load() != kRsemMagic || validate_sem(s, why, sizeof why) != 0) return;
    if (lock_acquire_recovery(v, &s->lock, rt) == -ETIMEDOUT) return;
    if (s->lock.dirty.load()) repair_locked(s);
    std::uint32_t passed = 0;
    for (Waiter& w : s->w) {
        if (w.owner.load() != make_token(dead_slot, dead_gen)) continue;
        const std::uint32_t st = w.state.load();
        if (st == kWaiting) s->nwaiting.fetch_sub(1);
        if (st == kGranted) ++passed;
        w.state.store(kFree);
    }
    lock_clear_dirty(&s->lock);
    Waiter* to_wake[CHM_RSEM_WAITERS];
    std::uint32_t n = 0;
    for (; passed; --passed) {
        Waiter* w = nullptr;
        give_locked(s, &w);
        if (w) to_wake[n++] = w;
    }
    lock_release(&s->lock);
    for (std::uint32_t i = 0; i < n; ++i)
        wake_granted(grant_of(s, to_wake[i]), owner_slot(to_wake[i]),
                     recorded(to_wake[i]));
}

int rsem_validate(const View& v, std::uint32_t off, std::uint32_t size, const char* name, char* why, std::size_t n) {
    char what[160];
    int r = 0;
    if (size < kAllocSize) {
        std::snprintf(what, sizeof what, "size %u, smaller than a remote semaphore (%u)", size, kAllocSize);
        r = kCorrupt;
    } else if (const Rsem* s = rsem_at(v.at<char>(off)); s->magic.load(std::memory_order_relaxed) != kRsemMagic) {
        std::snprintf(what, sizeof what, "magic is 0x%08x, expected 0x%08x", s->magic.load(std::memory_order_relaxed), kRsemMagic);
        r = kCorrupt;
    } else {
        r = validate_sem(s, what, sizeof what);
    }
    if (r) std::snprintf(why, n, "%s: %s", name, what);
    return r;
}

void rsem_check(const View& v, std::uint32_t off, std::uint32_t size, const char* name, Report& r) {
    constexpr auto R = std::memory_order_relaxed;
    if (size < kAllocSize) return r.problem("%s: %u bytes, smaller than a remote semaphore", name, size);
    const Rsem* s = rsem_at(v.at<char>(off));
    if (s->magic.load(R) != kRsemMagic) return r.problem("%s: no remote-semaphore magic", name);
    const std::uint32_t kind = s->kind.load(R);
    if (kind != CHM_SEM_BINARY && kind != CHM_SEM_COUNTING) return r.problem("%s: kind %u is not a semaphore kind", name, kind);
    if (s->broken.load(R)) r.problem("%s: marked broken", name);
    const std::uint32_t nwaiting = s->nwaiting.load(R), seq = s->seq.load(R);
    const std::uint32_t tok = s->lock.token.load(std::memory_order_acquire);
    if (tok && bp::token_alive(v, tok, true)) return;  // a live holder may be mid-change
    // A lock its dead holder (or an ended task) left dirty: the next user
    // repairs the semaphore, so a grant it left half done is not damage.
    const bool repairable = tok && s->lock.dirty.load(R);
    char what[160];
    std::snprintf(what, sizeof what, "%s.lock", name);
    check_lock(v, s->lock, what, r);
    const std::uint32_t count = s->count.load(R);
    if (kind == CHM_SEM_BINARY && count > 1) r.problem("%s: binary, count %u", name, count);
    std::uint32_t waiting = 0, half = 0, half_at = 0;
    for (std::uint32_t i = 0; i < CHM_RSEM_WAITERS; ++i) {
        const Waiter& w = s->w[i];
        const std::uint32_t st = w.state.load(R);
        if (st == kFree) continue;
        if (st != kWaiting && st != kGranted) {
            r.problem("%s: waiter %u has state %u", name, i, st);
            continue;
        }
        waiting += st == kWaiting;
        if (half_granted(s, w) && !half++) half_at = i;
        const std::uint32_t owner = w.owner.load(R), slot = token_slot(owner);
        if (slot >= v.slots() || !token_alive(v, owner, true))
            r.problem("%s: waiter %u (%s) belongs to slot %u generation %u, not a live process", name, i,
                      st == kWaiting ? "waiting" : "granted", slot, owner & kGenMask);
    }
    if (s->nwaiting.load(R) != waiting) r.problem("%s: nwaiting %u, %u records waiting", name, s->nwaiting.load(R), waiting);
    // Judged only when no V ran across the scan (a V landing between
    // reading a record's state and its word would look half done).
    std::atomic_thread_fence(std::memory_order_acquire);
    const bool still = s->lock.token.load(R) == tok && s->nwaiting.load(R) == nwaiting && s->seq.load(R) == seq;
    if (half && !repairable && still)
        r.problem("%s: waiter %u (and %u more) is GRANTED but its grant word was never stored, on a lock not left "
                  "dirty: nobody will finish that grant",
                  name, half_at, half - 1);
    if (count > 0 && waiting > 0) r.problem("%s: count %u while %u waiters wait", name, count, waiting);
}

}  // namespace chm::ipc

using namespace chm::ipc;

extern "C" {

static int rsem_create_impl(const char* name, enum chm_sem_kind kind, uint32_t initial, int where,
                            chm_rsem_t** out) {
    if (!name || !out || (kind != CHM_SEM_BINARY && kind != CHM_SEM_COUNTING) ||
        (kind == CHM_SEM_BINARY && initial > 1)) {
        set_error("chm_rsem_create: NULL name or out, unknown kind, or a binary count above 1");
        return -EINVAL;
    }
    Attachment* a = current();
    if (!a) return set_error("chm_rsem_create: not attached to a backplane"), -ENOTCONN;
    if (where != CHM_SHM_COMMON && (where < 0 || std::uint32_t(where) >= a->slots())) {
        set_error("chm_rsem_create %s: where %d is neither CHM_SHM_COMMON nor an RTPU", name, where);
        return -ECHRNG;
    }
    int r = registry_lock(*a, a->token);
    if (r) return set_error("chm_rsem_create %s: registry lock", name), r;
    EntryInfo info{};
    r = registry_create_locked(*a, a->token, kKindRemoteSem, name, kAllocSize,
                               where == CHM_SHM_COMMON ? kWhereCommon : std::uint32_t(where),
                               a->slot, &info);
    if (r == 0) {
        // Not findable by name until the registry lock is released.
        Rsem* s = rsem_at(a->at<char>(info.offset));
        s->kind.store(kind);
        s->count.store(initial);
        s->nwaiting.store(0);
        s->seq.store(0);
        s->broken.store(0);
        for (Waiter& w : s->w) w.state.store(kFree);
        s->lock.token.store(0);
        s->magic.store(kRsemMagic, std::memory_order_release);
        a->local_refs[info.index] = 1;
        *out = reinterpret_cast<chm_rsem_t*>(a->at<char>(info.offset));
    }
    registry_unlock(*a);
    switch (r) {
    case 0: break;
    case -EEXIST: set_error("chm_rsem_create: the name \"%s\" is taken", name); break;
    case -ENAMETOOLONG: set_error("chm_rsem_create: name longer than %u", kNameMax); break;
    case -ENOMEM: set_error("chm_rsem_create %s: no room in that memory", name); break;
    case -ENOSPC: set_error("chm_rsem_create %s: the registry is full", name); break;
    case -EBADMSG: {  // a corrupt arena: its check said which field
        char why[400];
        std::snprintf(why, sizeof why, "%s", chm_bp_last_error());
        set_error("chm_rsem_create %s: %s", name, why);
        break;
    }
    default: set_error("chm_rsem_create %s: error %d", name, r); break;
    }
    return r;
}

static int rsem_open_impl(const char* name, chm_rsem_t** out) {
    if (!name || !out) return set_error("chm_rsem_open: NULL name or out"), -EINVAL;
    Attachment* a = current();
    if (!a) return set_error("chm_rsem_open: not attached to a backplane"), -ENOTCONN;
    int r = registry_lock(*a, a->token);
    if (r) return r;
    const int i = registry_find_locked(*a, name, kKindRemoteSem);
    std::uint32_t off = 0, size = 0;
    char why[200];
    if (i >= 0) {
        r = entry_payload(*a, std::uint32_t(i), kAllocSize, &off, &size, why, sizeof why);
        if (r == 0) {
            const Rsem* s = rsem_at(a->at<char>(off));
            if (s->magic.load() != kRsemMagic)
                r = corrupt(why, sizeof why, "magic is 0x%08x, expected 0x%08x", s->magic.load(), kRsemMagic);
            else
                r = validate_sem(s, why, sizeof why);
        }
        if (r == 0) {
            registry_ref_locked(*a, std::uint32_t(i));
            *out = reinterpret_cast<chm_rsem_t*>(a->base + off);
        }
    }
    registry_unlock(*a);
    if (i < 0) return set_error("chm_rsem_open: no remote semaphore \"%s\"", name), -ENOENT;
    if (r) set_error("chm_rsem_open: remote semaphore \"%s\" (registry[%d]): %s", name, i, why);
    return r;
}

static int rsem_p_impl(chm_rsem_t* h, WaitLimit limit) {
    Rsem* s = from_handle(h);
    if (!s) return set_error("chm_rsem_p: not a remote semaphore handle"), -EINVAL;
    Attachment* a = current();
    chm::kernel::CallScope in_call;  // a destroy or abort-cycle meanwhile waits for the return
    std::uint64_t budget;
    const LockWait how = p_wait(limit, &budget);
    if (int r = lock(s, how, budget)) return r;
    if (s->count.load() > 0) {  // the fast path: one lock, no system call
        s->count.store(s->count.load(std::memory_order_relaxed) - 1, std::memory_order_relaxed);  // lock held
        unlock(s);
        return 0;
    }
    if (limit.kind == WaitLimit::kNoWait) {
        unlock(s);
        return -EAGAIN;
    }
    const std::uint64_t deadline = limit.deadline();
    if (deadline != CHM_FOREVER && wait_now() >= deadline) {  // a deadline already past
        unlock(s);
        return -ETIMEDOUT;
    }
    Waiter* me = nullptr;
    for (Waiter& w : s->w) {
        if (w.state.load() == kFree) {
            me = &w;
            break;
        }
    }
    if (!me) {
        unlock(s);
        set_error("chm_rsem_p: %d tasks wait already", CHM_RSEM_WAITERS);
        return -ENOSPC;
    }
    // Everything local first, then the shared words in one short burst of
    // plain stores (the unlock publishes them): a peer spinning on the lock
    // steals its line between our writes, and each write after that costs
    // a cache miss while we hold it.
    const std::uint32_t initial = wait_word_initial();
    const std::uint32_t prio = std::uint32_t(chm::kernel::remote_waiter_priority());
    const WaiterId who = waiter_self();
    constexpr auto R = std::memory_order_relaxed;
    lock_mark_dirty(&s->lock);
    const std::uint32_t seq = s->seq.load(R) + 1;
    s->seq.store(seq, R);
    s->nwaiting.store(s->nwaiting.load(R) + 1, R);
    CHM_STOP_POINT("rsem.p.locked");  // mid-change: nwaiting counts a record not yet waiting
    std::uint32_t* const grant = grant_of(s, me);
    __atomic_store_n(grant, initial, __ATOMIC_RELAXED);
    me->owner.store(a->token, R);
    me->prio.store(prio, R);
    me->seq.store(seq, R);
    me->task.store(who.task, R);
    me->urgency.store(who.urgency, R);
    me->state.store(kWaiting, R);
    lock_clear_dirty(&s->lock);
    unlock(s);

    (void)chm::kernel::hold_add(withdraw_abandoned, me, std::uint32_t(me - s->w));  // however the task ends
    CHM_STOP_POINT("rsem.p.wait");
    int r = wait_word(grant, deadline);
    chm::kernel::hold_drop(me);

    // Granted: the granter already took the record off the waiting list
    // (kGranted, nwaiting), so giving it back needs no lock: a hand-off
    // costs one lock round trip per side instead of two.
    if (chm::kernel::word_granted(__atomic_load_n(grant, __ATOMIC_ACQUIRE))) {
        me->state.store(kFree, std::memory_order_release);
        return 0;
    }
    if (int e = lock(s)) return e;
    if (chm::kernel::word_granted(__atomic_load_n(grant, __ATOMIC_SEQ_CST))) {
        r = 0;  // granted, perhaps just as the wait timed out
    } else if (me->state.load() == kWaiting) {
        s->nwaiting.fetch_sub(1);
    }
    me->state.store(kFree);
    unlock(s);
    return r;
}

static int rsem_v_impl(chm_rsem_t* h) {
    Rsem* s = from_handle(h);
    if (!s) return set_error("chm_rsem_v: not a remote semaphore handle"), -EINVAL;
    chm::kernel::CallScope in_call;
    if (int r = lock(s, LockWait::kRelease)) return r;
    CHM_STOP_POINT("rsem.v.locked");
    Waiter* w = nullptr;
    const int r = give_locked(s, &w);
    unlock_and_wake(s, w);
    if (r) set_error("chm_rsem_v: the count would overflow");
    return r;
}

static int rsem_value_impl(chm_rsem_t* h) {
    Rsem* s = from_handle(h);
    if (!s) return -EINVAL;
    const std::uint32_t c = s->count.load();
    return c > INT_MAX ? INT_MAX : int(c);
}

static int rsem_waiting_impl(chm_rsem_t* h) {
    Rsem* s = from_handle(h);
    return s ? int(s->nwaiting.load()) : -EINVAL;
}

static int rsem_close_impl(chm_rsem_t* h) {
    Rsem* s = from_handle(h);
    if (!s) return set_error("chm_rsem_close: not a remote semaphore handle"), -EINVAL;
    Attachment* a = current();
    int r = registry_lock(*a, a->token);
    if (r) return r;
    // A handle this process did not open (or closed already) is no error
    // here: the semaphore lives on either way.
    registry_unref_locked(*a, a->off_of(h), kKindRemoteSem);
    registry_unlock(*a);
    return 0;
}

static int rsem_destroy_impl(const char* name) {
    if (!name) return set_error("chm_rsem_destroy: NULL name"), -EINVAL;
    Attachment* a = current();
    if (!a) return -ENOTCONN;
    int r = registry_lock(*a, a->token);
    if (r) return r;
    const int i = registry_find_locked(*a, name, kKindRemoteSem);
    if (i >= 0) registry_destroy_locked(*a, std::uint32_t(i), a->token);
    registry_unlock(*a);
    if (i < 0) return set_error("chm_rsem_destroy: no remote semaphore \"%s\"", name), -ENOENT;
    return 0;
}

}  // extern "C"

// The public calls: each leaves through ipc::leave, which turns a failure
// into an error signal of module "ipc" under global handling
// (ipc/err/report.hpp). Every lock the call took is released by then.
extern "C" {

int chm_rsem_create(const char* name, enum chm_sem_kind kind, uint32_t initial, int where,
                    chm_rsem_t** out) {
    return chm::ipc::leave(rsem_create_impl(name, kind, initial, where, out), "chm_rsem_create");
}
int chm_rsem_open(const char* name, chm_rsem_t** out) {
    return chm::ipc::leave(rsem_open_impl(name, out), "chm_rsem_open");
}
int chm_rsem_p_timed(chm_rsem_t* sem, uint64_t timeout_ns) {
    return chm::ipc::leave(rsem_p_impl(sem, wait_for(timeout_ns)), "chm_rsem_p_timed");
}
int chm_rsem_p_until(chm_rsem_t* sem, uint64_t deadline_ns) {
    return chm::ipc::leave(rsem_p_impl(sem, wait_until(deadline_ns)), "chm_rsem_p_until");
}
int chm_rsem_p(chm_rsem_t* sem) { return chm::ipc::leave(rsem_p_impl(sem, wait_for(CHM_FOREVER)), "chm_rsem_p"); }
int chm_rsem_try_p(chm_rsem_t* sem) {
    return chm::ipc::leave(rsem_p_impl(sem, wait_for(CHM_NO_WAIT)), "chm_rsem_try_p");
}
int chm_rsem_v(chm_rsem_t* sem) { return chm::ipc::leave(rsem_v_impl(sem), "chm_rsem_v"); }
int chm_rsem_value(chm_rsem_t* sem) { return chm::ipc::leave(rsem_value_impl(sem), "chm_rsem_value"); }
int chm_rsem_waiting(chm_rsem_t* sem) { return chm::ipc::leave(rsem_waiting_impl(sem), "chm_rsem_waiting"); }
int chm_rsem_close(chm_rsem_t* sem) { return chm::ipc::leave(rsem_close_impl(sem), "chm_rsem_close"); }
int chm_rsem_destroy(const char* name) { return chm::ipc::leave(rsem_destroy_impl(name), "chm_rsem_destroy"); }

}  // extern "C"
