// Sending and receiving (chm_msgq_send* / chm_msgq_receive*). The path
// that need not wait reads like a fast path: a few guards, one robust
// lock, the copy, a wake-up only if a waiter record says someone waits,
// unlock. Waiting registers a record in the queue and parks the task (or
// sleeps on the futex) through ipc/wake; see msgq.hpp for the protocol.
#include <cerrno>
#include <cstring>
#include <ctime>

#include "chimera/bp.h"
#include "chimera/kernel.h"
#include "chimera/task.h"
#include "ipc/backplane/stop_point.hpp"
#include "ipc/err/report.hpp"
#include "ipc/msgq/msgq.hpp"
#include "ipc/wake/wake.hpp"
#include "kernel/sync/remote_wait.hpp"
#include "kernel/task/holds.hpp"

namespace chm::ipc::msgq {

namespace {

constexpr auto R = std::memory_order_relaxed;

std::uint32_t* word_of(A32& a) { return reinterpret_cast<std::uint32_t*>(&a); }

// a more urgent than b: higher priority, then the earlier ticket.
bool more_urgent(const Waiter* a, const Waiter* b) {
    const auto pa = std::int32_t(a->prio.load(R)), pb = std::int32_t(b->prio.load(R));
    if (pa != pb) return pa > pb;
    return std::int32_t(a->ticket.load(R) - b->ticket.load(R)) < 0;
}

A32& waiting_of(QueueHeader* q, std::uint32_t state) {
    return state == kWaiterRecv ? q->recv_waiting : q->send_waiting;
}

void free_record_locked(QueueHeader* q, Waiter* w) {
    const std::uint32_t st = w->state.load(R);
    if (st == kWaiterFree) return;
    w->state.store(kWaiterFree, R);
    bump(waiting_of(q, st), std::uint32_t(-1));
}

bool has_room(const QueueHeader* q, const Geo& g, std::uint32_t len) {
    return q->free_head.load(R) != kNil && q->bytes.load(R) + len <= g.max_bytes;
}

// The data path reads two kinds of index from shared memory: list heads
// and tails, and the free list's head. Each is bounded by one compare
// against the process-local slot count before it addresses a slot (a
// slot's `next` is only followed by becoming one of them).
int put_locked(const bp::View& v, QueueHeader* q, const Geo& g, std::uint32_t sender, std::uint32_t type,
               std::uint32_t prio, const void* data, std::uint32_t len) {
    const std::uint32_t i = q->free_head.load(R);
    const std::uint32_t l = level_of(g, prio);
    const std::uint32_t t = q->tail(l).load(R);
    if (i >= g.max_count || (t != kNil && t >= g.max_count)) [[unlikely]] {
        set_corrupt(v, q, i >= g.max_count ? "free_head is %u, outside its %u slots" : "tail is %u, outside its %u slots",
                    i >= g.max_count ? i : t, g.max_count);
        return bp::kCorrupt;
    }
    MsgSlot* s = slot_at(q, g, i);
    q->free_head.store(s->next.load(R), R);
    s->type.store(type, R);
    s->len.store(len, R);
    s->prio.store(prio, R);
    s->seq.store(bump(q->next_seq, 1), R);
    s->sender.store(sender, R);
    // A bad user buffer faulted before the lock (probe_readable); one
    // unmapped since would fault in this copy and end the task here, the
    // slot off the free list and the lock dirty: the task's hold list
    // orphans the lock and its next user rebuilds the lists.
    CHM_STOP_POINT("msgq.send.copy");
    if (len) std::memcpy(payload_of(s), data, len);
    s->state.store(kSlotQueued, std::memory_order_release);  // committed
    if (g.order == kLifo) {
        s->next.store(q->head(l).load(R), R);
        if (q->head(l).load(R) == kNil) q->tail(l).store(i, R);
        q->head(l).store(i, R);
    } else {
        s->next.store(kNil, R);
        if (t == kNil) q->head(l).store(i, R);
        else slot_at(q, g, t)->next.store(i, R);
        q->tail(l).store(i, R);
    }
    set_bits(q->level_mask, 1u << l);
    bump(q->count, 1);
    bump(q->bytes, len);
    bump(q->sent, 1);
    return 0;
}

// The next message's slot index (the queue is not empty).
std::uint32_t next_index(const QueueHeader* q, const Geo& g, std::uint32_t* level) {
    const std::uint32_t mask = q->level_mask.load(R);
    // mask | 1: a corrupt empty mask gives level 0, whose head is bounded.
    const std::uint32_t l = g.order == kPriority ? 31u - std::uint32_t(__builtin_clz(mask | 1u)) : 0u;
    *level = l;
    return q->head(l).load(R);
}

void fill_info(MsgSlot* s, chm_msgq_msg_info_t* info) {
    if (!info) return;
    info->type = s->type.load(R);
    info->prio = s->prio.load(R);
    info->len = s->len.load(R);
    info->sender = std::int32_t(s->sender.load(R));
}

// Take the next message into buf: its length, or -EMSGSIZE (left queued).
int get_locked(const bp::View& v, QueueHeader* q, const Geo& g, void* buf, std::size_t size,
               chm_msgq_msg_info_t* info) {
    std::uint32_t l;
    const std::uint32_t i = next_index(q, g, &l);
    if (i >= g.max_count) [[unlikely]] {
        set_corrupt(v, q, "head[%u] is %u, outside its %u slots", l, i, g.max_count);
        return bp::kCorrupt;
    }
    MsgSlot* s = slot_at(q, g, i);
    const std::uint32_t len = s->len.load(R);
    if (len > g.max_msg) [[unlikely]] {
        set_corrupt(v, q, "slot %u: len %u above max_msg %u", i, len, g.max_msg);
        return bp::kCorrupt;
    }
    fill_info(s, info);
    if (len > size) return -EMSGSIZE;
    const std::uint32_t next = s->next.load(R);
    q->head(l).store(next, R);
    if (next == kNil) {
        q->tail(l).store(kNil, R);
        clear_bits(q->level_mask, 1u << l);
    }
    CHM_STOP_POINT("msgq.receive.copy");
    if (len) std::memcpy(buf, payload_of(s), len);
    s->state.store(kSlotFree, std::memory_order_release);  // released
    s->next.store(q->free_head.load(R), R);
    q->free_head.store(i, R);
    bump(q->count, std::uint32_t(-1));
    bump(q->bytes, 0u - len);
    bump(q->received, 1);
    return int(len);
}

std::int32_t my_priority(bool task) { return task ? kernel::remote_waiter_priority() : 0; }

WaiterId recorded(const Waiter* w) { return WaiterId{w->task.load(R), w->urgency.load(R)}; }

// A free record for the caller, its word at `initial_word` (wait_word_initial),
// or nullptr (all taken: the caller polls).
Waiter* register_locked(QueueHeader* q, const Geo& g, std::uint32_t state, std::uint32_t me, WaiterId who,
                        std::int32_t prio, std::uint32_t initial_word) {
    for (std::uint32_t i = 0; i < g.max_waiters; ++i) {
        Waiter* w = waiter_at(q, g, i);
        if (w->state.load(R) != kWaiterFree) continue;
        std::uint32_t t = q->next_ticket.load(R);
        while (!kernel::word_granted(t)) ++t;  // a grant value
        w->word.store(initial_word, R);
        w->ticket.store(t, R);
        w->token.store(me, R);
        w->task.store(who.task, R);
        w->prio.store(std::uint32_t(prio), R);
        w->urgency.store(who.urgency, R);
        w->state.store(state, std::memory_order_release);
        bump(waiting_of(q, state), 1);
        // The ticket counter last: a checker whose before-and-after stamp
        // (validate_entry) saw it unchanged saw no registration land
        // halfway through its walk.
        q->next_ticket.store(t + 1, std::memory_order_release);
        return w;
    }
    return nullptr;
}

// A handle is the queue's address; it resolves through the process's
// record of the queue's open (Attachment::objects, found by the entry
// index the header carries, itself bounded by the local registry size):
// the geometry the open validated, or nullptr for anything this process
// has not opened.
QueueHeader* handle_queue(const bp::Attachment* a, chm_msgq_t* h, const Geo** g) {
    const char* p = reinterpret_cast<const char*>(h);
    if (!p || p < a->base || std::uint32_t(p - a->base) > a->size - sizeof(QueueHeader) ||
        (std::uint32_t(p - a->base) & 15) != 0)
        return nullptr;
    auto* q = reinterpret_cast<QueueHeader*>(const_cast<char*>(p));
    const std::uint32_t e = q->entry.load(R);
    if (e >= a->geo().registry_capacity) return nullptr;
    const bp::Attachment::OpenObject& o = a->objects[e];
    if (o.offset != std::uint32_t(p - a->base) || o.kind != bp::kKindMsgQueue) return nullptr;
    *g = reinterpret_cast<const Geo*>(o.words);
    return q;
}

int bad_handle(const char* fn, chm_msgq_t* h) {
    bp::set_error("%s: %p is not an open message queue", fn, static_cast<void*>(h));
    return -EINVAL;
}

// The open queue whose waiter records hold `w`, or nullptr.
QueueHeader* queue_of_record(const bp::Attachment* a, const void* w, const Geo** g) {
    const std::uint32_t n = a->geo().registry_capacity;
    for (std::uint32_t e = 0; e < n; ++e) {
        const bp::Attachment::OpenObject& o = a->objects[e];
        if (o.kind != bp::kKindMsgQueue) continue;
        const Geo* og = reinterpret_cast<const Geo*>(o.words);
        auto* q = reinterpret_cast<QueueHeader*>(a->base + o.offset);
        const char* lo = reinterpret_cast<const char*>(waiter_at(q, *og, 0));
        const char* p = static_cast<const char*>(w);
        if (p >= lo && p < lo + std::size_t(og->max_waiters) * sizeof(Waiter) &&
            (p - lo) % sizeof(Waiter) == 0) {
            *g = og;
            return q;
        }
    }
    return nullptr;
}

// A task ended waiting (an abort or an exception in a handler run at the
// wait; kernel/task/holds.hpp): its record `w` of `ticket` is withdrawn
// as a timed-out waiter's would be, and a grant it held passes to the
// next live waiter of its direction.
void withdraw_abandoned(void* w, std::uint32_t ticket) {
    const bp::Attachment* a = bp::current();
    const Geo* g;
    QueueHeader* q = a ? queue_of_record(a, w, &g) : nullptr;
    if (!q || lock_queue(*a, q, *g, a->token) != 0) return;
    auto* r = static_cast<Waiter*>(w);
    WakeBuf<2> wakes;
    const std::uint32_t st = r->state.load(R);
    if (st != kWaiterFree && r->ticket.load(R) == ticket && r->token.load(R) == a->token) {
        const bool granted = r->word.load(R) == ticket;
        bp::lock_mark_dirty(&q->lock);
        free_record_locked(q, r);
        if (granted && (st == kWaiterRecv ? q->count.load(R) != 0 : q->free_head.load(R) != kNil))
            grant_one_locked(*a, q, *g, st, &wakes);
        bp::lock_clear_dirty(&q->lock);
    }
    unlock_queue(q);
    wakes.deliver();
}

// The two directions of the queue, so send and receive share one wait
// loop (a template: the hot path is inlined, no indirect calls).
struct SendOp {
    static constexpr std::uint32_t kMine = kWaiterSend, kOther = kWaiterRecv;
    static void wait_point() { CHM_STOP_POINT("msgq.send.wait"); }
    std::uint32_t sender, type, prio, len;
    const void* data;
    bool ready(const QueueHeader* q, const Geo& g) const { return has_room(q, g, len); }
    int act(const bp::View& v, QueueHeader* q, const Geo& g) const {
        return put_locked(v, q, g, sender, type, prio, data, len);
    }
};

struct RecvOp {
    static constexpr std::uint32_t kMine = kWaiterRecv, kOther = kWaiterSend;
    static void wait_point() { CHM_STOP_POINT("msgq.receive.wait"); }
    void* buf;
    std::size_t size;
    chm_msgq_msg_info_t* info;
    bool ready(const QueueHeader* q, const Geo&) const { return q->count.load(R) != 0; }
    int act(const bp::View& v, QueueHeader* q, const Geo& g) const { return get_locked(v, q, g, buf, size, info); }
};

// The whole operation, lock to unlock. A task destroyed or whose cycle is
// aborted meanwhile ends when it returns (kernel/task/holds.hpp).
template <class Op>
int run(const bp::Attachment* a, QueueHeader* q, const Geo& g, const Op& op, WaitLimit limit) {
    kernel::CallScope in_call;
    int r = lock_queue(*a, q, g, a->token, &limit);
    if (r) return r;
    CHM_STOP_POINT("msgq.run.locked");
    WakeBuf<2> wakes;
    // The path that needs no wait.
    if (!q->destroyed.load(R) && op.ready(q, g)) {
        bp::lock_mark_dirty(&q->lock);
        r = op.act(*a, q, g);
        if (r >= 0 && waiting_of(q, Op::kOther).load(R)) grant_one_locked(*a, q, g, Op::kOther, &wakes);
        bp::lock_clear_dirty(&q->lock);
        unlock_queue(q);
        wakes.deliver();
        return r;
    }
    // Waiting.
    const WaiterId who = waiter_self();
    const bool task = who.as_task();
    const std::int32_t prio = my_priority(task);
    // The deadline on wait_word's clock, fixed once: every round of the
    // loop (a grant another caller took first, a poll) counts against it.
    const std::uint64_t deadline = limit.deadline();
    bool timed_out = false;
    for (;;) {
        if (q->destroyed.load(R)) {
            r = -EIDRM;
            break;
        }
        if (op.ready(q, g)) {
            bp::lock_mark_dirty(&q->lock);
            r = op.act(*a, q, g);
            if (r >= 0 && waiting_of(q, Op::kOther).load(R)) grant_one_locked(*a, q, g, Op::kOther, &wakes);
            bp::lock_clear_dirty(&q->lock);
            break;
        }
        if (limit.kind == WaitLimit::kNoWait) {
            r = -EAGAIN;
            break;
        }
        std::uint64_t left = CHM_FOREVER;  // for the poll below
        if (deadline != CHM_FOREVER) {
            const std::uint64_t now = wait_now();
            if (timed_out || now >= deadline) {  // a deadline past at entry: no wait
                r = -ETIMEDOUT;
                break;
            }
            left = deadline - now;
        }
        const std::uint32_t initial = wait_word_initial();
        bp::lock_mark_dirty(&q->lock);
        Waiter* w = register_locked(q, g, Op::kMine, a->token, who, prio, initial);
        const std::uint32_t ticket = w ? w->ticket.load(R) : 0;
        bp::lock_clear_dirty(&q->lock);
        unlock_queue(q);
        int wr;
        if (w) {
            (void)kernel::hold_add(withdraw_abandoned, w, ticket);  // however the task ends while it waits
            Op::wait_point();
            wr = wait_word(word_of(w->word), deadline);
            kernel::hold_drop(w);
        } else {  // every record taken: poll
            bp::relinquish(left < 1000000 ? left : 1000000);
            wr = 0;
        }
        if ((r = lock_queue(*a, q, g, a->token)) != 0) return r;
        if (w && w->ticket.load(R) == ticket && w->token.load(R) == a->token) {
            bp::lock_mark_dirty(&q->lock);
            free_record_locked(q, w);
            bp::lock_clear_dirty(&q->lock);
        }
        if (wr == -ETIMEDOUT) timed_out = true;
        if (wr == -EINTR) {
            r = -EINTR;
            break;
        }
    }
    // Leaving without acting while the condition holds: a grant this
    // caller may have taken passes to the next waiter of its direction.
    if (r < 0 && r != -EIDRM && r != bp::kCorrupt && op.ready(q, g) && waiting_of(q, Op::kMine).load(R)) {
        bp::lock_mark_dirty(&q->lock);
        grant_one_locked(*a, q, g, Op::kMine, &wakes);
        bp::lock_clear_dirty(&q->lock);
    }
    unlock_queue(q);
    wakes.deliver();
    return r;
}

// Touch every page of the caller's buffer before the queue's lock is
// taken, so a bad buffer (unmapped, or read-only for a receive) faults in
// the caller's task with nothing held, not in the copy under the lock. A
// 4 KiB stride touches every page whatever the host's page size. A buffer
// unmapped by another task between this and the copy still faults under
// the lock: the task's hold list covers that (kernel/task/holds.hpp).
constexpr std::uintptr_t kProbeStride = 4096;

void probe_readable(const void* p, std::size_t n) {
    if (!n) return;
    auto* c = static_cast<const volatile char*>(p);
    for (std::size_t off = 0; off < n; off += kProbeStride - (reinterpret_cast<std::uintptr_t>(c + off) % kProbeStride))
        (void)c[off];
    (void)c[n - 1];
}

void probe_writable(void* p, std::size_t n) {
    if (!n) return;
    auto* c = static_cast<volatile char*>(p);
    // Written back as read: the caller's bytes are unchanged.
    for (std::size_t off = 0; off < n; off += kProbeStride - (reinterpret_cast<std::uintptr_t>(c + off) % kProbeStride))
        c[off] = c[off];
    c[n - 1] = c[n - 1];
}

int send_common(const char* fn, chm_msgq_t* h, std::uint32_t type, std::uint32_t prio, const void* data,
                std::size_t len, WaitLimit limit) {
    bp::Attachment* a = bp::current();
    if (!a) return bp::set_error("%s: not attached to a backplane", fn), -ENOTCONN;
    const Geo* g;
    QueueHeader* q = handle_queue(a, h, &g);
    if (!q) return bad_handle(fn, h);
    if (prio > CHM_MSGQ_PRIO_MAX || (!data && len))
        return bp::set_error("%s: priority %u above %d, or NULL data", fn, prio, CHM_MSGQ_PRIO_MAX), -EINVAL;
    if (len > g->max_msg || len > g->max_bytes)
        return bp::set_error("%s: %zu bytes, the queue takes at most %u", fn, len,
                             g->max_msg < g->max_bytes ? g->max_msg : g->max_bytes), -EMSGSIZE;
    probe_readable(data, len);
    const SendOp op{a->slot, type, prio, std::uint32_t(len), data};
    return run(a, q, *g, op, limit);
}

int recv_common(const char* fn, chm_msgq_t* h, void* buf, std::size_t size, chm_msgq_msg_info_t* info,
                WaitLimit limit) {
    bp::Attachment* a = bp::current();
    if (!a) return bp::set_error("%s: not attached to a backplane", fn), -ENOTCONN;
    const Geo* g;
    QueueHeader* q = handle_queue(a, h, &g);
    if (!q) return bad_handle(fn, h);
    if (!buf && size) return bp::set_error("%s: NULL buffer", fn), -EINVAL;
    probe_writable(buf, size < g->max_msg ? size : g->max_msg);  // no message is longer
    const RecvOp op{buf, size, info};
    return run(a, q, *g, op, limit);
}

}  // namespace

// ------------------------------------------------------------- internals

void Wakes::add(const Wake& x) {
    if (n < cap) {
        w[n++] = x;
        return;
    }
    wake_granted(x.word, x.slot, x.who);  // no room to defer: wake now
}

void Wakes::deliver() {
    for (std::uint32_t i = 0; i < n; ++i) wake_granted(w[i].word, w[i].slot, w[i].who);
    n = 0;
}

int lock_queue(const bp::View& v, QueueHeader* q, const Geo& g, std::uint32_t me, const WaitLimit* limit) {
    bool own = false;  // the call's own timeout is the bound
    const std::uint64_t bound = limit ? limit->lock_budget(bp::kInternalTimeoutNs, &own) : bp::kInternalTimeoutNs;
    const bool try_call = limit && limit->kind == WaitLimit::kNoWait;
    const int r = bound == 0 ? bp::lock_acquire_brief(v, &q->lock, me, bp::kTryLockNs)
                             : bp::lock_acquire(v, &q->lock, me, kLockPollNs, bound);
    if (r == -EBUSY && try_call) {
        char who[48];
        bp::lock_holder(&q->lock, who, sizeof who);
        bp::set_error("message queue: its lock is held by %s, a live peer: a try call does not wait", who);
        return -EAGAIN;
    }
    if (r == -EBUSY || (r == -ETIMEDOUT && own)) {  // a deadline reached, or the call's timeout ran out
        char who[48];
        bp::lock_holder(&q->lock, who, sizeof who);
        bp::set_error("message queue: its lock was held by %s, a live peer, past the call's timeout", who);
        return -ETIMEDOUT;
    }
    if (r == -ETIMEDOUT) {
        char who[48];
        bp::lock_holder(&q->lock, who, sizeof who);
        bp::set_error("message queue: its lock was held by %s, a live peer, past %s", who,
                      bp::masked_wait() ? "20 us (interrupts masked)" : "5 s");
        return -EDEADLK;
    }
    if (r == -EOWNERDEAD) {
        // The holder died: rebuild what it may have left half-changed.
        if (q->lock.dirty.load(std::memory_order_acquire) && !q->broken.load(R)) rebuild_locked(q, g);
        bp::lock_clear_dirty(&q->lock);
    }
    if (q->broken.load(R)) {
        bp::lock_release(&q->lock);
        bp::set_error("message queue: damaged by a process that died in it");
        return -ENOTRECOVERABLE;
    }
    return 0;
}

void unlock_queue(QueueHeader* q) { bp::lock_release(&q->lock); }

bool grant_one_locked(const bp::View& v, QueueHeader* q, const Geo& g, std::uint32_t state, Wakes* out) {
    Waiter* best = nullptr;
    for (std::uint32_t i = 0; i < g.max_waiters; ++i) {
        Waiter* w = waiter_at(q, g, i);
        if (w->state.load(R) != state || w->word.load(R) == w->ticket.load(R)) continue;
        if (!bp::token_alive(v, w->token.load(R), false)) {
            free_record_locked(q, w);  // its process died; recovery has not run yet
            continue;
        }
        if (!best || more_urgent(w, best)) best = w;
    }
    if (!best) return false;
    const std::uint32_t t = best->ticket.load(R);
    if (!store_grant(word_of(best->word), t))
        out->add(Wake{word_of(best->word), t, bp::token_slot(best->token.load(R)), recorded(best)});
    return true;
}

void grant_all_locked(QueueHeader* q, const Geo& g, Wakes* out) {
    for (std::uint32_t i = 0; i < g.max_waiters; ++i) {
        Waiter* w = waiter_at(q, g, i);
        if (w->state.load(R) == kWaiterFree) continue;
        const std::uint32_t t = w->ticket.load(R);
        if (!store_grant(word_of(w->word), t))
            out->add(Wake{word_of(w->word), t, bp::token_slot(w->token.load(R)), recorded(w)});
    }
}

void purge_token_locked(const bp::View& v, QueueHeader* q, const Geo& g, std::uint32_t token, Wakes* out) {
    std::uint32_t passed[2] = {0, 0};  // grants the dead held: receivers, senders
    for (std::uint32_t i = 0; i < g.max_waiters; ++i) {
        Waiter* w = waiter_at(q, g, i);
        const std::uint32_t st = w->state.load(R);
        if (st == kWaiterFree || w->token.load(R) != token) continue;
        if (w->word.load(R) == w->ticket.load(R)) ++passed[st == kWaiterRecv ? 0 : 1];
        free_record_locked(q, w);
    }
    // Each grant a dead waiter took and never used goes to a live one, as
    // long as there is something to take (messages) or room to send into.
    for (std::uint32_t k = 0; k < passed[0] && q->count.load(R) != 0; ++k)
        if (!grant_one_locked(v, q, g, kWaiterRecv, out)) break;
    for (std::uint32_t k = 0; k < passed[1] && q->free_head.load(R) != kNil; ++k)
        if (!grant_one_locked(v, q, g, kWaiterSend, out)) break;
}

}  // namespace chm::ipc::msgq

using namespace chm::ipc::msgq;
using chm::ipc::wait_for;
using chm::ipc::wait_until;

// The public calls leave through ipc::leave: a failure becomes an error
// signal of module "ipc" under global handling (ipc/err/report.hpp), once
// send_common / recv_common have released the queue's lock.
extern "C" {

int chm_msgq_send(chm_msgq_t* q, std::uint32_t type, std::uint32_t prio, const void* data, size_t len) {
    return chm::ipc::leave(send_common("chm_msgq_send", q, type, prio, data, len, wait_for(CHM_FOREVER)),
                           "chm_msgq_send");
}

int chm_msgq_send_timed(chm_msgq_t* q, std::uint32_t type, std::uint32_t prio, const void* data, size_t len,
                        std::uint64_t timeout_ns) {
    return chm::ipc::leave(send_common("chm_msgq_send_timed", q, type, prio, data, len, wait_for(timeout_ns)),
                           "chm_msgq_send_timed");
}

int chm_msgq_send_until(chm_msgq_t* q, std::uint32_t type, std::uint32_t prio, const void* data, size_t len,
                        std::uint64_t deadline_ns) {
    return chm::ipc::leave(send_common("chm_msgq_send_until", q, type, prio, data, len, wait_until(deadline_ns)),
                           "chm_msgq_send_until");
}

int chm_msgq_try_send(chm_msgq_t* q, std::uint32_t type, std::uint32_t prio, const void* data, size_t len) {
    return chm::ipc::leave(send_common("chm_msgq_try_send", q, type, prio, data, len, wait_for(CHM_NO_WAIT)),
                           "chm_msgq_try_send");
}

int chm_msgq_receive(chm_msgq_t* q, void* buf, size_t size, chm_msgq_msg_info_t* info) {
    return chm::ipc::leave(recv_common("chm_msgq_receive", q, buf, size, info, wait_for(CHM_FOREVER)),
                           "chm_msgq_receive");
}

int chm_msgq_receive_timed(chm_msgq_t* q, void* buf, size_t size, chm_msgq_msg_info_t* info,
                           std::uint64_t timeout_ns) {
    return chm::ipc::leave(recv_common("chm_msgq_receive_timed", q, buf, size, info, wait_for(timeout_ns)),
                           "chm_msgq_receive_timed");
}

int chm_msgq_receive_until(chm_msgq_t* q, void* buf, size_t size, chm_msgq_msg_info_t* info,
                           std::uint64_t deadline_ns) {
    return chm::ipc::leave(recv_common("chm_msgq_receive_until", q, buf, size, info, wait_until(deadline_ns)),
                           "chm_msgq_receive_until");
}

int chm_msgq_try_receive(chm_msgq_t* q, void* buf, size_t size, chm_msgq_msg_info_t* info) {
    return chm::ipc::leave(recv_common("chm_msgq_try_receive", q, buf, size, info, wait_for(CHM_NO_WAIT)),
                           "chm_msgq_try_receive");
}

}  // extern "C"
