// Validation of a message queue found in backplane memory: its geometry
// (read_geometry: copied out of the header, then checked, so what was
// checked is what is used) and its indices (validate_locked). A queue is
// checked when a process opens it; afterwards the data path uses the
// process-local geometry and bounds the one or two indices it reads from
// shared memory per call (queue.cpp). A failure is bp::kCorrupt with a
// text naming the queue and the field.
#include <array>
#include <atomic>
#include <cstdarg>
#include <cstdio>

#include "ipc/backplane/stop_point.hpp"
#include "ipc/msgq/msgq.hpp"

namespace chm::ipc::msgq {

namespace {

constexpr auto R = std::memory_order_relaxed;
using bp::corrupt;


bool index_ok(std::uint32_t i, const Geo& g) { return i == kNil || i < g.max_count; }

}  // namespace

void set_corrupt(const bp::View& v, const QueueHeader* q, const char* fmt, ...) {
    char what[200];
    va_list ap;
    va_start(ap, fmt);
    std::vsnprintf(what, sizeof what, fmt, ap);
    va_end(ap);
    bp::set_error("message queue at offset %u: %s", v.off_of(q), what);
}

int read_geometry(const QueueHeader* q, std::uint32_t payload_size, Geo* out, char* why, std::size_t n) {
    const Geo g{q->order, q->max_msg, q->max_count, q->max_bytes, q->slot_size, q->max_waiters, q->slots_off,
                q->waiters_off};
    const std::uint32_t total = q->total_size;
    if (g.order > kPriority) return corrupt(why, n, "order is %u, not FIFO, LIFO or PRIORITY", g.order);
    if (g.max_msg < 1 || g.max_msg > CHM_MSGQ_MSG_MAX) return corrupt(why, n, "max_msg is %u, not 1..%u", g.max_msg, CHM_MSGQ_MSG_MAX);
    if (g.max_count < 1 || g.max_count > CHM_MSGQ_COUNT_MAX)
        return corrupt(why, n, "max_count is %u, not 1..%u", g.max_count, CHM_MSGQ_COUNT_MAX);
    if (g.max_waiters < 1 || g.max_waiters > CHM_MSGQ_WAITERS_MAX)
        return corrupt(why, n, "max_waiters is %u, not 1..%u", g.max_waiters, CHM_MSGQ_WAITERS_MAX);
    if (g.max_bytes < 1) return corrupt(why, n, "max_bytes is 0");
    const std::uint32_t slot = std::uint32_t(sizeof(MsgSlot)) + ((g.max_msg + 15u) & ~15u);
    if (g.slot_size != slot) return corrupt(why, n, "slot_size is %u, max_msg %u implies %u", g.slot_size, g.max_msg, slot);
    if (g.slots_off != sizeof(QueueHeader))
        return corrupt(why, n, "slots_off is %u, expected %u", g.slots_off, unsigned(sizeof(QueueHeader)));
    // max_count and max_msg are bounded above, so this sum cannot wrap in 64 bits.
    const std::uint64_t waiters = std::uint64_t(g.slots_off) + std::uint64_t(g.max_count) * g.slot_size;
    if (g.waiters_off != waiters)
        return corrupt(why, n, "waiters_off is %u, the slots end at %llu", g.waiters_off, static_cast<unsigned long long>(waiters));
    const std::uint32_t size = queue_size(g.max_msg, g.max_count, g.max_waiters);
    if (size == 0 || total != size) return corrupt(why, n, "total_size is %u, the geometry implies %u", total, size);
    if (total > payload_size)
        return corrupt(why, n, "total_size %u exceeds the %u bytes its registry entry holds", total, payload_size);
    *out = g;
    return 0;
}

int validate_locked(QueueHeader* q, const Geo& g, char* why, std::size_t n) {
    const std::uint32_t fh = q->free_head.load(R);
    if (!index_ok(fh, g)) return corrupt(why, n, "free_head is %u, outside its %u slots", fh, g.max_count);
    const std::uint32_t mask = q->level_mask.load(R);
    if (g.order != kPriority && (mask & ~1u)) return corrupt(why, n, "level_mask 0x%08x: only level 0 is used", mask);
    std::uint32_t queued = 0;
    for (std::uint32_t l = 0; l < kLevels; ++l) {
        const std::uint32_t h = q->head(l).load(R), t = q->tail(l).load(R);
        if (!index_ok(h, g)) return corrupt(why, n, "head[%u] is %u, outside its %u slots", l, h, g.max_count);
        if (!index_ok(t, g)) return corrupt(why, n, "tail[%u] is %u, outside its %u slots", l, t, g.max_count);
        if ((h == kNil) != (t == kNil) || (h != kNil) != ((mask >> l) & 1))
            return corrupt(why, n, "head[%u] %u, tail[%u] %u and level_mask 0x%08x disagree", l, h, l, t, mask);
        std::uint32_t last = kNil, steps = 0;
        for (std::uint32_t i = h; i != kNil; i = slot_at(q, g, i)->next.load(R)) {
            if (!index_ok(i, g)) return corrupt(why, n, "list %u: slot %u links to %u, outside its slots", l, last, i);
            if (++steps > g.max_count) return corrupt(why, n, "list %u loops", l);
            MsgSlot* s = slot_at(q, g, i);
            if (s->state.load(R) != kSlotQueued) return corrupt(why, n, "slot %u on list %u: state 0x%08x is not QUEUED", i, l, s->state.load(R));
            if (s->len.load(R) > g.max_msg) return corrupt(why, n, "slot %u: len %u above max_msg %u", i, s->len.load(R), g.max_msg);
            if (s->prio.load(R) > CHM_MSGQ_PRIO_MAX || level_of(g, s->prio.load(R)) != l)
                return corrupt(why, n, "slot %u: prio %u does not belong on list %u", i, s->prio.load(R), l);
            last = i;
        }
        if (t != last) return corrupt(why, n, "tail[%u] is %u, the list ends at %u", l, t, last);
        queued += steps;
    }
    std::uint32_t frees = 0;
    for (std::uint32_t i = fh, prev = kNil; i != kNil; prev = i, i = slot_at(q, g, i)->next.load(R)) {
        if (!index_ok(i, g)) return corrupt(why, n, "free list: slot %u links to %u, outside its slots", prev, i);
        if (++frees > g.max_count) return corrupt(why, n, "free list loops");
        if (slot_at(q, g, i)->state.load(R) != kSlotFree) return corrupt(why, n, "free list: slot %u is not FREE", i);
    }
    if (queued + frees != g.max_count)
        return corrupt(why, n, "%u slots queued and %u free, of %u: a slot is on no list", queued, frees, g.max_count);
    if (q->count.load(R) != queued) return corrupt(why, n, "count is %u, the lists hold %u", q->count.load(R), queued);
    std::uint32_t recv = 0, send = 0;
    for (std::uint32_t i = 0; i < g.max_waiters; ++i) {
        const std::uint32_t st = waiter_at(q, g, i)->state.load(R);
        if (st > kWaiterSend) return corrupt(why, n, "waiter %u: state %u is not FREE, RECV or SEND", i, st);
        recv += st == kWaiterRecv;
        send += st == kWaiterSend;
    }
    CHM_STOP_POINT("msgq.validate.scanned");
    if (q->recv_waiting.load(R) != recv || q->send_waiting.load(R) != send)
        return corrupt(why, n, "recv_waiting %u / send_waiting %u, the records say %u / %u", q->recv_waiting.load(R),
                       q->send_waiting.load(R), recv, send);
    return 0;
}

int validate_entry(const bp::View& v, std::uint32_t off, std::uint32_t size, const char* name, char* why,
                   std::size_t n) {
    if (size < sizeof(QueueHeader)) return corrupt(why, n, "%s: %u bytes, smaller than a queue header", name, size);
    auto* q = v.at<QueueHeader>(off);
    if (q->magic.load(std::memory_order_acquire) != kMagic) return 0;  // stillborn: the next open removes it
    char what[200];
    Geo g;
    int r = read_geometry(q, size, &g, what, sizeof what);
    // The lists are walked without the lock (a checker may not take it): a
    // verdict counts only when the lock was free and no send, receive or
    // repair happened and no waiter record was taken or given back from
    // before the walk to after it; otherwise the queue was mid-change (a
    // dead holder's is rebuilt by whoever robs the lock) and the walk is
    // tried again, a few times, then only the geometry stands. (Before, a
    // send landing during the walk read as corruption: "count is 1, the
    // lists hold 0"; and a receiver registering or withdrawing during it,
    // "recv_waiting 1 / send_waiting 0, the records say 0 / 0": the waiting
    // counts and the ticket counter joined the stamp; test_ipc_races.cpp.)
    // Every change stores the counters it moves after the structure, the
    // ticket counter last, so a stamp that reads one new sees its change.
    constexpr auto A = std::memory_order_acquire;
    for (int attempt = 0; r == 0 && attempt < 8; ++attempt) {
        const auto stamp = [q] {
            return std::array<std::uint32_t, 8>{q->lock.token.load(A),   q->sent.load(A),
                                                 q->received.load(A),     q->repairs.load(A),
                                                 q->broken.load(A),       q->next_ticket.load(A),
                                                 q->recv_waiting.load(A), q->send_waiting.load(A)};
        };
        const auto before = stamp();
        if (before[0] != 0 || before[4] != 0) break;  // held or broken: geometry only
        const int walked = validate_locked(q, g, what, sizeof what);
        std::atomic_thread_fence(std::memory_order_acquire);
        if (stamp() == before) {
            r = walked;
            break;
        }
    }
    if (r) corrupt(why, n, "%s: %s", name, what);
    return r;
}

}  // namespace chm::ipc::msgq
