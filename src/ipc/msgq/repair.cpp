// A queue's layout, its repair after a holder died mid-change, the
// recovery callback of its registry kind, and the strict checker.
//
// Repair rebuilds every derived field from the message slots (msgq.hpp):
// the slots whose state is QUEUED are the queue, in the order their
// sequence numbers give (ages counted back from next_seq, so the 32-bit
// wrap does not matter), sorted in place by a merge sort of the linked
// list (no memory: it may run in a task that robbed the lock). Anything
// that cannot be read as a queue (a slot state that is neither FREE nor
// QUEUED, a length or priority out of range, header geometry that does not
// add up) marks the queue broken: later calls get -ENOTRECOVERABLE.
#include <atomic>
#include <cerrno>
#include <cstdio>

#include "ipc/msgq/msgq.hpp"

namespace chm::ipc::msgq {

namespace {

constexpr auto R = std::memory_order_relaxed;

std::uint32_t round16(std::uint32_t n) { return (n + 15u) & ~15u; }

// Older first (FIFO, and FIFO among equal priorities) or newer first (LIFO).
struct Age {
    const Geo& g;
    std::uint32_t now;
    bool newest_first;
    std::uint32_t of(QueueHeader* q, std::uint32_t i) const { return now - slot_at(q, g, i)->seq.load(R); }
    bool before(QueueHeader* q, std::uint32_t a, std::uint32_t b) const {
        return newest_first ? of(q, a) < of(q, b) : of(q, a) > of(q, b);
    }
};

// Stable bottom-up merge sort of the list starting at `head` (links in
// MsgSlot::next). Returns the new head; *tail_out its last element.
std::uint32_t sort_list(QueueHeader* q, std::uint32_t head, const Age& age, std::uint32_t* tail_out) {
    *tail_out = kNil;
    if (head == kNil) return kNil;
    for (std::uint32_t insize = 1;; insize *= 2) {
        std::uint32_t p = head, tail = kNil, merges = 0;
        head = kNil;
        while (p != kNil) {
            ++merges;
            std::uint32_t qq = p, psize = 0;
            for (std::uint32_t i = 0; i < insize && qq != kNil; ++i) {
                ++psize;
                qq = slot_at(q, age.g, qq)->next.load(R);
            }
            std::uint32_t qsize = insize;
            while (psize > 0 || (qsize > 0 && qq != kNil)) {
                std::uint32_t e;
                if (psize == 0) {
                    e = qq, qq = slot_at(q, age.g, qq)->next.load(R), --qsize;
                } else if (qsize == 0 || qq == kNil || !age.before(q, qq, p)) {
                    e = p, p = slot_at(q, age.g, p)->next.load(R), --psize;
                } else {
                    e = qq, qq = slot_at(q, age.g, qq)->next.load(R), --qsize;
                }
                if (tail == kNil) head = e;
                else slot_at(q, age.g, tail)->next.store(e, R);
                tail = e;
            }
            p = qq;
        }
        slot_at(q, age.g, tail)->next.store(kNil, R);
        if (merges <= 1) {
            *tail_out = tail;
            return head;
        }
    }
}

std::atomic<bool> g_registered{false};

// Every process that uses message queues can recover them (and the line
// for kBuiltinRecovery lets every survivor do it).
[[maybe_unused]] const bool g_static_registration = (ensure_recovery_registered(), true);

}  // namespace

std::uint32_t queue_size(std::uint32_t max_msg, std::uint32_t max_count, std::uint32_t max_waiters) {
    const std::uint64_t slot = sizeof(MsgSlot) + std::uint64_t(round16(max_msg));
    const std::uint64_t n = sizeof(QueueHeader) + slot * max_count + std::uint64_t(sizeof(Waiter)) * max_waiters;
    return n > 0xF0000000ull ? 0 : std::uint32_t(n);
}

void queue_init(QueueHeader* q, std::uint32_t order, std::uint32_t max_msg, std::uint32_t max_count,
                std::uint32_t max_bytes, std::uint32_t max_waiters) {
    q->order = order;
    q->max_msg = max_msg;
    q->max_count = max_count;
    q->max_bytes = max_bytes;
    q->slot_size = std::uint32_t(sizeof(MsgSlot)) + round16(max_msg);
    q->max_waiters = max_waiters;
    q->slots_off = sizeof(QueueHeader);
    q->waiters_off = q->slots_off + max_count * q->slot_size;
    q->total_size = queue_size(max_msg, max_count, max_waiters);
    for (std::uint32_t l = 0; l < kLevels; ++l) {
        q->head(l).store(kNil, R);
        q->tail(l).store(kNil, R);
    }
    const Geo g{order, max_msg, max_count, max_bytes, q->slot_size, max_waiters, q->slots_off, q->waiters_off};
    for (std::uint32_t i = 0; i < max_count; ++i) {
        MsgSlot* s = slot_at(q, g, i);
        s->state.store(kSlotFree, R);
        s->next.store(i + 1 < max_count ? i + 1 : kNil, R);
    }
    q->free_head.store(0, R);
    q->next_ticket.store(1, R);
    q->magic.store(kMagic, std::memory_order_release);
}

bool rebuild_locked(QueueHeader* q, const Geo& g) {
    // 1. Validate every slot and thread the queued ones onto unsorted
    //    per-level lists, the free ones onto the free list.
    std::uint32_t heads[kLevels], free_head = kNil, count = 0, bytes = 0, mask = 0;
    for (std::uint32_t l = 0; l < kLevels; ++l) heads[l] = kNil;
    for (std::uint32_t i = g.max_count; i-- > 0;) {
        MsgSlot* s = slot_at(q, g, i);
        const std::uint32_t st = s->state.load(R);
        if (st == kSlotFree) {
            s->next.store(free_head, R);
            free_head = i;
            continue;
        }
        const std::uint32_t len = s->len.load(R), prio = s->prio.load(R);
        if (st != kSlotQueued || len > g.max_msg || prio > CHM_MSGQ_PRIO_MAX) {
            q->broken.store(1, R);
            return false;
        }
        const std::uint32_t l = level_of(g, prio);
        s->next.store(heads[l], R);
        heads[l] = i;
        mask |= 1u << l;
        ++count;
        bytes += len;
    }
    // 2. Order each level by age.
    const Age age{g, q->next_seq.load(R), g.order == kLifo};
    for (std::uint32_t l = 0; l < kLevels; ++l) {
        std::uint32_t tail;
        q->head(l).store(sort_list(q, heads[l], age, &tail), R);
        q->tail(l).store(tail, R);
    }
    q->free_head.store(free_head, R);
    q->level_mask.store(mask, R);
    q->count.store(count, R);
    q->bytes.store(bytes, R);
    // 3. Waiter records: a state other than the three is a record torn
    //    mid-write by its owner's death: free it. Recount the rest.
    std::uint32_t nrecv = 0, nsend = 0;
    for (std::uint32_t i = 0; i < g.max_waiters; ++i) {
        Waiter* w = waiter_at(q, g, i);
        const std::uint32_t st = w->state.load(R);
        if (st == kWaiterRecv) ++nrecv;
        else if (st == kWaiterSend) ++nsend;
        else if (st != kWaiterFree) w->state.store(kWaiterFree, R);
    }
    q->recv_waiting.store(nrecv, R);
    q->send_waiting.store(nsend, R);
    if (q->next_ticket.load(R) == 0) q->next_ticket.store(1, R);
    q->repairs.fetch_add(1, R);
    return true;
}

void recover(const bp::View& v, std::uint32_t entry_index, std::uint32_t dead_slot, std::uint32_t dead_gen,
             std::uint32_t recovery_token) {
    bp::RegistryEntry* e = v.entry(entry_index);
    std::uint32_t off, size;
    char why[200];
    // An entry whose payload is not a block of its arena is not followed.
    if (bp::entry_payload(v, entry_index, sizeof(QueueHeader), &off, &size, why, sizeof why) != 0) return;
    auto* q = v.at<QueueHeader>(off);
    const std::uint32_t dead = bp::make_token(dead_slot, dead_gen);
    if (q->magic.load(std::memory_order_acquire) != kMagic) {
        // Its creator died between publishing the name and writing the
        // header: nobody ever had it. The registry frees it.
        if (e->owner.load(R) == dead) bp::registry_destroy_locked(v, entry_index, recovery_token);
        return;
    }
    Geo g;
    if (read_geometry(q, size, &g, why, sizeof why) != 0) return;  // corrupt: its open says so; nothing to follow
    const int r = bp::lock_acquire_recovery(v, &q->lock, recovery_token);
    if (r == -ETIMEDOUT) return;  // a live holder: the next granter drops the dead waiters
    if (r == -EOWNERDEAD && q->lock.dirty.load(std::memory_order_acquire) && !q->broken.load(R)) rebuild_locked(q, g);
    bp::lock_clear_dirty(&q->lock);
    WakeBuf<CHM_MSGQ_WAITERS_MAX> wakes;
    // Granting walks the waiter records only, but only a queue whose
    // indices hold is touched at all.
    if (!q->broken.load(R) && validate_locked(q, g, why, sizeof why) == 0) {
        bp::lock_mark_dirty(&q->lock);
        purge_token_locked(v, q, g, dead, &wakes);
        bp::lock_clear_dirty(&q->lock);
    }
    bp::lock_release(&q->lock);
    wakes.deliver();
}

void ensure_recovery_registered() {
    if (g_registered.load(std::memory_order_acquire)) return;
    bp::register_recovery(bp::kKindMsgQueue, recover);
    g_registered.store(true, std::memory_order_release);
}

void check_entry(const bp::View& v, std::uint32_t off, std::uint32_t size, const char* name, bp::Report& r) {
    if (size < sizeof(QueueHeader)) return r.problem("%s: %u bytes, smaller than a queue header", name, size);
    const auto* q = v.at<QueueHeader>(off);
    const std::uint32_t tok = q->lock.token.load(R);
    if (tok && bp::token_alive(v, tok, true)) return;  // a live holder may be mid-change
    check_queue(v, q, size, name, r);
}

void check_queue(const bp::View& v, const QueueHeader* cq, std::uint32_t payload_size, const char* name,
                 bp::Report& rep) {
    auto* q = const_cast<QueueHeader*>(cq);  // read only: slot_at wants a mutable header
    if (q->magic.load(R) != kMagic) return rep.problem("%s: no queue magic (creator died while creating?)", name);
    Geo g;
    char why[200];
    if (read_geometry(q, payload_size, &g, why, sizeof why) != 0) return rep.problem("%s: %s", name, why);
    if (q->broken.load(R)) return rep.problem("%s: marked broken", name);
    char what[160];
    std::snprintf(what, sizeof what, "%s.lock", name);
    bp::check_lock(v, q->lock, what, rep);
    // Every list: in range, QUEUED, on its level, in order, tail right.
    const Age age{g, q->next_seq.load(R), g.order == kLifo};
    std::uint32_t seen = 0, bytes = 0, mask = 0;
    for (std::uint32_t l = 0; l < kLevels; ++l) {
        std::uint32_t i = q->head(l).load(R), last = kNil, steps = 0;
        if (i != kNil) mask |= 1u << l;
        for (; i != kNil; i = slot_at(q, g, i)->next.load(R)) {
            if (i >= g.max_count || ++steps > g.max_count)
                return rep.problem("%s: list %u runs out of range or loops", name, l);
            MsgSlot* s = slot_at(q, g, i);
            if (s->state.load(R) != kSlotQueued) rep.problem("%s: list %u holds slot %u not QUEUED", name, l, i);
            if (level_of(g, s->prio.load(R)) != l) rep.problem("%s: slot %u on level %u, priority %u", name, i, l, s->prio.load(R));
            if (last != kNil && age.before(q, i, last)) rep.problem("%s: list %u out of order at slot %u", name, l, i);
            bytes += s->len.load(R);
            last = i;
        }
        if (q->tail(l).load(R) != last) rep.problem("%s: tail of list %u is %u, the list ends at %u", name, l, q->tail(l).load(R), last);
        seen += steps;
    }
    std::uint32_t queued = 0, free_slots = 0;
    for (std::uint32_t i = 0; i < g.max_count; ++i) {
        const std::uint32_t st = slot_at(q, g, i)->state.load(R);
        if (st == kSlotQueued) ++queued;
        else if (st == kSlotFree) ++free_slots;
        else rep.problem("%s: slot %u has state %08x", name, i, st);
    }
    if (seen != queued) rep.problem("%s: %u slots QUEUED, %u on the lists", name, queued, seen);
    if (q->count.load(R) != queued) rep.problem("%s: count %u, %u queued", name, q->count.load(R), queued);
    if (q->bytes.load(R) != bytes) rep.problem("%s: bytes %u, %u queued", name, q->bytes.load(R), bytes);
    if (q->level_mask.load(R) != mask) rep.problem("%s: level mask %08x, lists say %08x", name, q->level_mask.load(R), mask);
    std::uint32_t nfree = 0;
    for (std::uint32_t i = q->free_head.load(R); i != kNil; i = slot_at(q, g, i)->next.load(R)) {
        if (i >= g.max_count || ++nfree > g.max_count) return rep.problem("%s: free list out of range or loops", name);
        if (slot_at(q, g, i)->state.load(R) != kSlotFree) rep.problem("%s: free list holds slot %u not FREE", name, i);
    }
    if (nfree != free_slots) rep.problem("%s: %u slots FREE, %u on the free list", name, free_slots, nfree);
    std::uint32_t nrecv = 0, nsend = 0;
    for (std::uint32_t i = 0; i < g.max_waiters; ++i) {
        Waiter* w = waiter_at(q, g, i);
        const std::uint32_t st = w->state.load(R);
        if (st == kWaiterFree) continue;
        if (st == kWaiterRecv) ++nrecv;
        else if (st == kWaiterSend) ++nsend;
        else rep.problem("%s: waiter %u has state %u", name, i, st);
        if (!bp::token_alive(v, w->token.load(R), true)) rep.problem("%s: waiter %u belongs to a dead slot", name, i);
    }
    if (q->recv_waiting.load(R) != nrecv || q->send_waiting.load(R) != nsend)
        rep.problem("%s: waiting counts %u/%u, records %u/%u", name, q->recv_waiting.load(R), q->send_waiting.load(R),
                    nrecv, nsend);
}

}  // namespace chm::ipc::msgq
