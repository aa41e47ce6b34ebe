// Remote semaphores: the checks and repairs (the calls are in rsem.cpp).
// The open-time validation, the repair after a holder left the lock dirty
// (a grant left half done is finished there), the recovery of a dead
// slot's records and the checker chimera-bpcheck runs.
#include <atomic>
#include <cerrno>
#include <cstdint>
#include <cstdio>

#include "ipc/backplane/stop_point.hpp"
#include "ipc/rsem/rsem.hpp"

using namespace chm::bp;

namespace chm::ipc {
namespace rsem {

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
    //
    // A whole change can still fall between the two readings of a free
    // lock. That is why every change stores the records first and the
    // counters (nwaiting, seq) after them, and this scan reads the
    // counters first and the records after them, each load acquiring:
    // counters read new come with their records, and a record read new
    // means the closing reads see its change's lock held or its counters
    // new. (Counters first in P let a registration held between the
    // reads show "nwaiting is 1, 0 records wait": test_ipc_races.cpp.)
    constexpr auto A = std::memory_order_acquire;
    for (int attempt = 0; attempt < 8; ++attempt) {
        const std::uint32_t token = s->lock.token.load(A);
        CHM_STOP_POINT("rsem.validate.lock_read");
        const std::uint32_t seq = s->seq.load(A), nwaiting = s->nwaiting.load(A), count = s->count.load(A);
        std::uint32_t waiting = 0;
        for (std::uint32_t i = 0; i < CHM_RSEM_WAITERS; ++i) {
            const std::uint32_t st = s->w[i].state.load(A);
            if (st > kGranted) return corrupt(why, n, "waiter %u: state %u is not FREE, WAITING or GRANTED", i, st);
            waiting += st == kWaiting;
        }
        CHM_STOP_POINT("rsem.validate.scanned");
        const bool stable = token == 0 && s->lock.token.load(A) == 0 && s->nwaiting.load(A) == nwaiting &&
                            s->count.load(A) == count && s->seq.load(A) == seq;
        if (!stable) continue;
        if (nwaiting != waiting) return corrupt(why, n, "nwaiting is %u, %u records wait", nwaiting, waiting);
        return 0;
    }
    return 0;
}

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

}  // namespace rsem

using namespace rsem;

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
        if (st == kGranted) ++passed;
        w.state.store(kFree);  // the record before nwaiting (validate_sem)
        if (st == kWaiting) s->nwaiting.fetch_sub(1);
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
