// Recovering a dead RTPU slot. Any survivor may find the death (its monitor
// thread, a locker, a process joining that slot). Who recovers is decided
// by one CAS on the slot's recoverer word (layout.hpp), which names the
// recoverer in the same step: from 0 for a fresh recovery, from a dead
// recoverer's word to take over. Only the holder of that word moves the
// slot to RECOVERING (a CAS bound to the generation) and works, under a
// recovery token of that slot (layout.hpp) that stays "alive" exactly while
// the slot is RECOVERING and its recoverer lives. If the recoverer dies too,
// the next survivor takes over; every step below is idempotent.
//
// What happens to a dead slot's things (docs/backplane.md, Backplane):
//  * locks it held: robbed and repaired (arenas rebuilt, half-changed
//    registry entries finished or undone); user spin-locks it held are
//    robbed lazily by their next locker, who gets -EOWNERDEAD;
//  * allocations it never committed: freed;
//  * its attachments: dropped (a destroyed object it held last is freed);
//  * named objects it created: kept (they belong to the system, as on
//    Chimera II, until someone destroys them);
//  * each object kind's own repair: its registered RecoverFn.
#include <cerrno>
#include <ctime>

#include <unistd.h>

#include "ipc/backplane/backplane.hpp"
#include "ipc/backplane/stop_point.hpp"
#include "ipc/xmail/xmail.hpp"

namespace chm::bp {

namespace {

constexpr auto R = std::memory_order_relaxed;

std::atomic<RecoverFn> g_fns[kKindMax];

// Kinds every survivor must be able to recover, whether or not it used
// them itself: later subsystems (remote semaphores, message queues) add
// their entry here.
struct Builtin {
    std::uint32_t kind;
    RecoverFn fn;
};
constexpr Builtin kBuiltinRecovery[] = {
    {kKindNone, nullptr},
    {kKindRemoteSem, chm::ipc::rsem_recover},
    {kKindMsgQueue, chm::ipc::msgq::recover},
    {kKindStateVars, chm::ipc::svar_recover},
};

RecoverFn recovery_fn(std::uint32_t kind) {
    if (kind >= kKindMax) return nullptr;
    if (RecoverFn f = g_fns[kind].load(std::memory_order_acquire)) return f;
    for (const Builtin& b : kBuiltinRecovery)
        if (b.kind == kind && b.fn) return b.fn;
    return nullptr;
}

// Take over a lock held by the dead slot (token D) for its recovery (token
// Rt). True when the lock is now ours.
bool adopt(Lock* l, std::uint32_t d, std::uint32_t rt) {
    std::uint32_t t = l->token.load(std::memory_order_acquire);
    if (t == rt) return true;  // a dead recoverer's, now ours
    return t == d && l->token.compare_exchange_strong(t, rt, std::memory_order_acquire, R);
}

// False when the attempt ran out of its bound (recover_slot's WaitBound)
// waiting for a lock a live process holds: the slot stays RECOVERING and
// the next survivor to look (a monitor scan, a locker) takes it over;
// every step is idempotent.
bool do_recover(const View& v, std::uint32_t slot, std::uint32_t gen) {
    const std::uint32_t d = make_token(slot, gen), rt = make_token(slot, gen, true);
    Header* h = v.hdr();

    // 1. Arenas the dead process held: repair from the chain, release.
    ArenaHeader* arenas[kMaxSlots + 1];
    std::uint32_t n = 0;
    arenas[n++] = v.common_arena();
    for (std::uint32_t s = 0; s < v.slots(); ++s) arenas[n++] = v.local_arena(s);
    for (std::uint32_t k = 0; k < n; ++k) {
        if (!adopt(&arenas[k]->lock, d, rt)) continue;
        if (arenas[k]->lock.dirty.load(std::memory_order_acquire)) arena_rebuild_locked(v, arenas[k]);
        lock_clear_dirty(&arenas[k]->lock);
        lock_release(&arenas[k]->lock);
    }

    // 2. The registry: adopt it or wait for its live holder; then repair,
    //    run each kind's recovery and drop the dead slot's attachments.
    if (!adopt(&h->registry_lock, d, rt) &&
        lock_acquire(v, &h->registry_lock, rt, kInternalPollNs, kInternalTimeoutNs) == -ETIMEDOUT)
        return false;
    registry_repair_locked(v, rt);
    for (std::uint32_t i = 0; i < v.geo().registry_capacity; ++i) {
        RegistryEntry* e = v.entry(i);
        const auto st = static_cast<EntryState>(e->state.load(R));
        if (st == EntryState::Free) continue;
        if (RecoverFn f = recovery_fn(e->kind.load(R))) f(v, i, slot, gen, rt);
        if (WaitBound::over()) {  // f may have given up on a lock: not finished
            registry_unlock(v);
            return false;
        }
        registry_detach_locked(v, i, slot, rt);
    }
    registry_unlock(v);

    // 3. Its express-mail requests in every ring, given up as a departing
    //    process's are: claimed or WRITING -> FREE, being served ->
    //    ABANDONED (that server frees it), a reply nobody will read ->
    //    FREE. Else they held a record of a live ring until its server
    //    next woke (or a sender found the ring full).
    //    A ring lock it held mid-claim is released: every claim step
    //    leaves a consistent record (xmail.hpp), so nothing to repair.
    for (std::uint32_t s = 0; s < v.slots(); ++s) {
        Lock* l = &v.ring(s)->lock;
        if (!adopt(l, d, rt)) continue;
        lock_clear_dirty(l);
        lock_release(l);
    }
    chm::xmail::withdraw(v, d);

    // 4. The slot itself: its name and kind stay for the status display.
    RtpuEntry* e = v.rtpu(slot);
    e->pid_start.store(0);
    e->pid.store(vacant_pid(gen), std::memory_order_release);
    e->tid.store(0, R);
    e->pending.store(0, R);
    e->idle.store(0, R);
    e->urgency.store(0, R);
    e->running.store(0, R);
    e->poll_ns.store(0, R);
    e->mailbox.fetch_add(1, R);
    h->recoveries.fetch_add(1, R);
    h->last_recovery_ms.store(mono_ms(), R);
    std::uint32_t st = make_status(gen, SlotState::Recovering);
    e->status.compare_exchange_strong(st, make_status(gen, SlotState::Dead), std::memory_order_acq_rel);
    return true;
}

}  // namespace

int register_recovery(std::uint32_t kind, RecoverFn fn) {
    if (kind == kKindNone || kind >= kKindMax) return -EINVAL;
    g_fns[kind].store(fn, std::memory_order_release);
    return 0;
}

void withdraw_departing(const View& v, std::uint32_t slot, std::uint32_t gen, std::uint32_t token) {
    // The same callbacks as a recovery, with the departing token as the
    // "recovery" token: each takes the object's lock under it (or adopts
    // it, when a task of ours was stopped holding it) and drops the
    // records named make_token(slot, gen) == token.
    for (std::uint32_t i = 0; i < v.hdr()->geo.registry_capacity; ++i) {
        RegistryEntry* e = v.entry(i);
        if (static_cast<EntryState>(e->state.load(R)) == EntryState::Free) continue;
        if (RecoverFn f = recovery_fn(e->kind.load(R))) f(v, i, slot, gen, token);
    }
    chm::xmail::withdraw(v, token);
}

bool recover_slot(const View& v, std::uint32_t slot, std::uint32_t gen) {
    if (slot >= v.slots()) return false;
    RtpuEntry* e = v.rtpu(slot);
    std::uint32_t st = e->status.load(std::memory_order_acquire);
    if (status_gen(st) != gen) return false;
    switch (status_state(st)) {
    case SlotState::Joining:
    case SlotState::Running:
    case SlotState::Leaving:
    case SlotState::Recovering:
        if (!slot_holder_dead(v, slot, st)) return false;
        break;
    default:
        return false;
    }
    // Claim the recovery. The word is per slot, not per generation: a live
    // holder (a recovery in progress, or one about to start or to release)
    // makes us back off; only a dead one's word is taken over.
    const std::uint32_t me = self_recoverer_word();
    std::uint32_t w = e->recoverer.load(std::memory_order_acquire);
    if (w != 0 && (w == me || recoverer_alive(w))) return false;
    if (!e->recoverer.compare_exchange_strong(w, me, std::memory_order_acq_rel)) return false;
    CHM_STOP_POINT("bp.recover.won");
    auto release = [&] {
        std::uint32_t mine = me;
        e->recoverer.compare_exchange_strong(mine, 0, std::memory_order_acq_rel);
    };
    // Now ours alone: move (slot, gen) to RECOVERING, or find it there (a
    // dead recoverer's work to finish). Anything else: it moved on.
    st = e->status.load(std::memory_order_acquire);
    const SlotState state = status_state(st);
    bool go = status_gen(st) == gen;
    if (go && state != SlotState::Recovering) {
        go = (state == SlotState::Joining || state == SlotState::Running || state == SlotState::Leaving) &&
             slot_holder_dead(v, slot, st) &&
             e->status.compare_exchange_strong(st, make_status(gen, SlotState::Recovering),
                                               std::memory_order_acq_rel);
    }
    if (go) {
        CHM_STOP_POINT("bp.recover.recovering");  // the slot RECOVERING, this process its recoverer
        // Bounded: a live process holding a lock the recovery needs (it
        // stalled inside a call) holds it up at most this long, then it is
        // left to the next survivor (do_recover).
        WaitBound bound(kInternalTimeoutNs);
        go = do_recover(v, slot, gen);
    }
    release();
    return go;
}

}  // namespace chm::bp
