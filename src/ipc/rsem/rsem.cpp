// Remote semaphores (chimera/rsem.h): the calls. The layout and the
// protocol are in rsem.hpp; the validation, the repair after a dirty lock,
// the recovery of a dead slot and the checker in check.cpp.
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
#include "ipc/rsem/rsem.hpp"
#include "kernel/sync/remote_wait.hpp"
#include "kernel/task/holds.hpp"

using namespace chm::bp;

struct chm_rsem;  // the handle is the shared object's address

namespace chm::ipc {
using namespace rsem;
namespace {

Rsem* from_handle(chm_rsem_t* h) {
    Attachment* a = current();
    if (!a || !h) return nullptr;
    const char* p = reinterpret_cast<const char*>(h);
    if (p < a->base || p + kAllocSize > a->base + a->size) return nullptr;
    Rsem* s = rsem_at(h);
    return s->magic.load(std::memory_order_relaxed) == kRsemMagic ? s : nullptr;
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

}  // namespace

// Give one unit: to the most urgent waiter (returned when it must be woken
// after the unlock: not when its RTPU polls its word) or to the count.
// Lock held.
int rsem::give_locked(Rsem* s, Waiter** woken) {
    *woken = nullptr;
    if (Waiter* w = most_urgent_locked(s)) {
        constexpr auto R = std::memory_order_relaxed;
        lock_mark_dirty(&s->lock);
        // Before the grant (whose exchange releases it): the waiter frees
        // its record after seeing the grant, without the lock. The record
        // before nwaiting, as in P.
        w->state.store(kGranted, std::memory_order_release);
        s->nwaiting.store(s->nwaiting.load(R) - 1, std::memory_order_release);
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

namespace {

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
        me->state.store(kFree);  // the record before nwaiting, as in P
        if (st == kWaiting) s->nwaiting.store(s->nwaiting.load() - 1);
        lock_clear_dirty(&s->lock);
        if (st == kGranted) (void)give_locked(s, &woken);  // (marks the lock dirty itself)
    }
    unlock_and_wake(s, woken);
}

}  // namespace

}  // namespace chm::ipc

using namespace chm::ipc;

extern "C" {

static int rsem_create_impl(const char* name, enum chm_sem_kind kind, uint32_t initial, int where,
                            chm_rsem_t** out) {
    chm::kernel::CallScope in_call;  // a destroy or abort-cycle meanwhile waits for the return
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
    chm::kernel::CallScope in_call;  // a destroy or abort-cycle meanwhile waits for the return
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
    // The record before the counters (nwaiting, seq), each release: the
    // checker that reads a free lock on both sides of its scan relies on
    // it (validate_sem, check.cpp).
    constexpr auto W = std::memory_order_release;
    lock_mark_dirty(&s->lock);
    // Locked and dirty, nothing stored yet: here a task's end (the only
    // way one ends inside this section is an injected fault) leaves no
    // half-made record that names it, and the next user's repair recounts.
    // (Before the records-first order this point sat after the counters:
    // test_ipc_races.cpp holds a registration here against the checker.)
    CHM_STOP_POINT("rsem.p.locked");
    const std::uint32_t seq = s->seq.load(R) + 1;
    std::uint32_t* const grant = grant_of(s, me);
    __atomic_store_n(grant, initial, __ATOMIC_RELAXED);
    me->owner.store(a->token, R);
    me->prio.store(prio, R);
    me->seq.store(seq, R);
    me->task.store(who.task, R);
    me->urgency.store(who.urgency, R);
    me->state.store(kWaiting, W);
    s->nwaiting.store(s->nwaiting.load(R) + 1, W);
    s->seq.store(seq, W);
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
        me->state.store(kFree);
    } else {
        const bool waiting = me->state.load() == kWaiting;
        me->state.store(kFree);  // the record before nwaiting, as in P
        if (waiting) s->nwaiting.fetch_sub(1);
    }
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
    chm::kernel::CallScope in_call;  // a destroy or abort-cycle meanwhile waits for the return
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
    chm::kernel::CallScope in_call;  // a destroy or abort-cycle meanwhile waits for the return
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
