// Express mail, the sender's side (xmail.hpp): claim a record of the
// target's ring, write and post the request, ring the target, wait for the
// reply in bounded slices while watching that the target lives, and give
// the record back. Also the reclaim of records whose owner died.
#include <cerrno>
#include <cstdarg>
#include <cstdio>
#include <cstring>

#include "chimera/irq.h"
#include "ipc/backplane/stop_point.hpp"
#include "ipc/wake/wake.hpp"
#include "ipc/xmail/xmail.hpp"
#include "kernel/task/holds.hpp"
#include "kernel/err/last.hpp"
#include "kernel.hpp"
#include "port.hpp"

namespace chm::xmail {

namespace {

constexpr auto R = std::memory_order_relaxed;
constexpr auto Acq = std::memory_order_acquire;
constexpr auto Rel = std::memory_order_release;

// A waiting sender looks at its target this often: a death is seen within
// one slice even when the reply's wake-up cannot reach the sender.
constexpr std::int64_t kSliceNs = 20'000'000;

thread_local char t_error[768];  // room for a loader message that names a long path

std::uint64_t now_ns() { return port::now_ns(); }

const char* state_name(bp::SlotState s) {
    switch (s) {
    case bp::SlotState::Free: return "free";
    case bp::SlotState::Joining: return "joining";
    case bp::SlotState::Running: return "running";
    case bp::SlotState::Leaving: return "leaving";
    case bp::SlotState::Dead: return "dead";
    case bp::SlotState::Recovering: return "being recovered";
    }
    return "in an unknown state";
}

// Under the ring lock: a FREE record, claimed for `token` (state WRITING,
// owner and stamp set before the state leaves FREE). nullptr: ring full.
Record* claim_locked(const bp::View& v, bp::RingHeader* ring, std::uint32_t token, std::uint32_t* seq_out) {
    const std::uint32_t cap = ring_capacity(v);
    const std::uint32_t start = ring->head.load(R) % cap;
    for (std::uint32_t k = 0; k < cap; ++k) {
        Record* r = record_at(v, ring, (start + k) % cap);
        if (phase_of(r->state.load(Acq)) != kFree) continue;
        std::uint32_t seq = (ring->head.fetch_add(1, R) + 1) & 0x0FFFFFFF;
        if (seq == 0) seq = 1;
        r->owner.store(token, R);
        r->stamp_ms.store(bp::mono_ms(), R);
        r->state.store(make_state(seq, kWriting), Rel);
        *seq_out = seq;
        return r;
    }
    return nullptr;
}

// The sender gives its record up (timeout, dead target). Returns true when
// the reply came in after all (the caller then takes it).
bool abandon(Record* r, std::uint32_t seq) {
    for (;;) {
        std::uint32_t st = r->state.load(Acq);
        if (seq_of(st) != seq) return false;  // already reclaimed by others
        switch (phase_of(st)) {
        case kWriting:
        case kPosted:
        case kStale:  // ours, set aside while we stalled: ours to free
            if (r->state.compare_exchange_strong(st, make_state(seq, kFree), Rel, R)) return false;
            break;
        case kServing:
            if (r->state.compare_exchange_strong(st, make_state(seq, kAbandoned), Rel, R)) return false;
            break;
        case kReplied:
            return true;
        default:
            return false;
        }
    }
}

int take_reply(Record* r, std::uint32_t seq, void* reply, std::uint32_t cap, std::uint32_t* reply_len) {
    const int status = r->status;
    std::uint32_t n = r->len;
    if (reply_len) *reply_len = n;
    if (n > cap) n = cap;
    if (reply && n) std::memcpy(reply, payload_of(r), n);
    r->state.store(make_state(seq, kFree), Rel);
    return status;
}

}  // namespace

void set_error(const char* fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    std::vsnprintf(t_error, sizeof t_error, fmt, ap);
    va_end(ap);
    kernel::err_last_set(t_error);  // chm_err_last
}

}  // namespace chm::xmail

extern "C" const char* chm_rtpu_last_error(void) { return chm::xmail::t_error; }

namespace chm::xmail {

unsigned reclaim(const bp::View& v, bp::RingHeader* ring) {
    unsigned freed = 0;
    const std::uint32_t now = bp::mono_ms();
    for (std::uint32_t i = 0; i < ring_capacity(v); ++i) {
        Record* r = record_at(v, ring, i);
        std::uint32_t st = r->state.load(Acq);
        const Phase p = phase_of(st);
        if (p != kWriting && p != kPosted && p != kReplied && p != kStale) continue;
        const std::uint32_t owner = r->owner.load(R);
        Phase to = kFree;
        if (bp::token_alive(v, owner, false)) {
            // Alive but stuck mid-write: set aside, not freed (xmail.hpp);
            // its post will fail (-ETIMEDOUT).
            if (p != kWriting || std::int32_t(now - r->stamp_ms.load(R)) <= std::int32_t(kStaleWriteMs)) continue;
            to = kStale;
        }
        if (r->state.compare_exchange_strong(st, make_state(seq_of(st), to), Rel, R)) ++freed;
    }
    return freed;
}

unsigned withdraw(const bp::View& v, std::uint32_t token) {
    unsigned n = 0;
    for (std::uint32_t s = 0; s < v.slots(); ++s) {
        bp::RingHeader* ring = v.ring(s);
        if (ring_record_size(v) < sizeof(Record)) continue;  // no express mail on this backplane
        for (std::uint32_t i = 0; i < ring_capacity(v); ++i) {
            Record* r = record_at(v, ring, i);
            const std::uint32_t st = r->state.load(Acq);
            const Phase p = phase_of(st);
            if (p == kFree || p == kAbandoned || r->owner.load(R) != token) continue;
            // abandon() leaves a reply that came in for the caller to read:
            // nobody will read this one.
            if (abandon(r, seq_of(st))) {
                std::uint32_t replied = make_state(seq_of(st), kReplied);
                r->state.compare_exchange_strong(replied, make_state(seq_of(st), kFree), Rel, R);
            }
            ++n;
        }
    }
    return n;
}

namespace {

// A request given up: not yet served -> FREE, being served -> ABANDONED
// (its server frees it), a reply nobody will read -> FREE.
void give_up(Record* r, std::uint32_t seq) {
    if (abandon(r, seq)) {
        std::uint32_t replied = make_state(seq, kReplied);
        r->state.compare_exchange_strong(replied, make_state(seq, kFree), Rel, R);
    }
}

// A task ended with request `p` of `seq` claimed or in flight (an abort or
// an exception; kernel/task/holds.hpp): its record is given up at once,
// not kept by the live process until the process leaves.
void give_up_abandoned(void* p, std::uint32_t seq) { give_up(static_cast<Record*>(p), seq); }

}  // namespace

int post(int rtpu, Kind kind, const void* req, std::uint32_t len, std::uint64_t timeout_ns, Pending* p) {
    t_error[0] = 0;
    p->r = nullptr;
    bp::Attachment* a = bp::current();
    if (!a) return set_error("not attached to a backplane"), -ENOTCONN;
    if (rtpu < 0 || std::uint32_t(rtpu) >= a->slots())
        return set_error("RTPU %d out of range (slots 0..%u)", rtpu, a->slots() - 1), -ECHRNG;
    if (port::on_kernel_thread() && kernel::g_k.in_irq)
        return set_error("express mail from an interrupt handler"), -EPERM;
    if (std::uint32_t(rtpu) == a->slot && port::on_kernel_thread() && !ipc::waits_as_task())
        return set_error("request to this RTPU from its kernel thread outside a task"), -EDEADLK;

    bp::RtpuEntry* e = a->rtpu(std::uint32_t(rtpu));
    const std::uint32_t st = e->status.load(Acq);
    const bp::SlotState state = bp::status_state(st);
    if (state != bp::SlotState::Running || e->kind.load(R) != std::uint32_t(bp::SlotKind::Rtpu)) {
        if (state == bp::SlotState::Running)
            set_error("slot %d is a host program, not an RTPU", rtpu);
        else
            set_error("RTPU %d is not running (slot %s)", rtpu, state_name(state));
        return -EHOSTDOWN;
    }
    bp::RingHeader* ring = a->ring(std::uint32_t(rtpu));
    const std::uint32_t rsize = ring_record_size(*a);
    if (rsize < kRecordMin)
        return set_error("ring records of %u bytes are below %u", rsize, kRecordMin), -EMSGSIZE;
    if (len > rsize - sizeof(Record))
        return set_error("request of %u bytes exceeds a ring record's %zu", len,
                         std::size_t(rsize - sizeof(Record))), -EMSGSIZE;

    const std::uint64_t start = now_ns();
    const std::uint64_t deadline = start + timeout_ns;

    // 1. Claim a record (wait, bounded, while the ring is full).
    Record* r = nullptr;
    std::uint32_t seq = 0;
    for (bool reclaimed = false;;) {
        const std::uint64_t now = now_ns();
        if (now >= deadline) return set_error("RTPU %d: ring full for the whole timeout", rtpu), -EBUSY;
        int lr = bp::lock_acquire(*a, &ring->lock, a->token, bp::kInternalPollNs, deadline - now);
        if (lr == -ETIMEDOUT) return set_error("RTPU %d: ring lock busy for the whole timeout", rtpu), -EBUSY;
        // -EOWNERDEAD: a sender died claiming; every claim step leaves a
        // consistent record, so there is nothing to repair.
        bp::lock_clear_dirty(&ring->lock);
        r = claim_locked(*a, ring, a->token, &seq);
        if (!r && !reclaimed) {
            reclaim(*a, ring);
            reclaimed = true;
            r = claim_locked(*a, ring, a->token, &seq);
        }
        if (r) {
            // The calling task holds the record from its claim on (until
            // await or cancel gives it back): one that ends between here
            // and the post gives it up, where before it stayed WRITING,
            // then STALE, until the process left.
            (void)kernel::hold_add(give_up_abandoned, r, seq);
            CHM_STOP_POINT("xmail.claim.locked");  // claimed (WRITING), the ring lock still held
        }
        bp::lock_release(&ring->lock);
        if (r) break;
        if (e->status.load(Acq) != st)
            return set_error("RTPU %d left or died (its ring was full)", rtpu), -EHOSTDOWN;
        bp::relinquish(1'000'000);
        reclaimed = false;
    }

    // 2. Write and post. The record stays ours while we write: a reclaim
    // can only set it STALE (xmail.hpp), never hand it to another sender.
    CHM_STOP_POINT("xmail.post.before_write");
    r->kind = kind;
    r->status = 0;
    r->len = len;
    r->server = 0;
    const ipc::WaiterId who = ipc::waiter_self();
    r->waiter_task.store(who.task, R);
    r->waiter_urgency.store(who.urgency, R);
    r->reply.store(0, R);
    if (len) std::memcpy(payload_of(r), req, len);
    std::uint32_t expect = make_state(seq, kWriting);
    if (!r->state.compare_exchange_strong(expect, make_state(seq, kPosted), Rel, R)) {
        kernel::hold_drop(r);
        (void)abandon(r, seq);  // STALE: ours to free
        return set_error("RTPU %d: request set aside as stale (the sender stalled over %u ms while "
                         "writing it); not sent", rtpu, kStaleWriteMs), -ETIMEDOUT;
    }
    if (ipc::wake_ring(std::uint32_t(rtpu), ipc::kVecExpressMail) == -EPERM) {
        // The slot's pid or thread id is not its member's (reported, last
        // error set): nobody we may wake would serve it.
        kernel::hold_drop(r);
        if (abandon(r, seq)) {
            std::uint32_t replied = make_state(seq, kReplied);  // nobody will read it
            r->state.compare_exchange_strong(replied, make_state(seq, kFree), Rel, R);
        }
        return -EPERM;
    }
    *p = Pending{r, seq, std::uint32_t(rtpu), st, deadline, timeout_ns};
    return 0;
}

int await(Pending* p, void* reply, std::uint32_t cap, std::uint32_t* reply_len) {
    t_error[0] = 0;
    if (reply_len) *reply_len = 0;
    Record* r = p->r;
    if (!r) return set_error("no request posted"), -EINVAL;
    p->r = nullptr;
    // Given back on every return below (taken, abandoned or left to the
    // server as ABANDONED).
    struct Drop {
        Record* r;
        ~Drop() { kernel::hold_drop(r); }
    } drop{r};
    const std::uint32_t seq = p->seq, st = p->status;
    const int rtpu = int(p->rtpu);
    const std::uint64_t deadline = p->deadline, timeout_ns = p->timeout_ns;
    bp::Attachment* a = bp::current();
    if (!a) return set_error("not attached to a backplane"), -ENOTCONN;
    bp::RtpuEntry* e = a->rtpu(p->rtpu);

    // 3. Wait for the reply, in slices, watching the target.
    auto* word = reinterpret_cast<std::uint32_t*>(&r->reply);
    for (;;) {
        if (phase_of(r->state.load(Acq)) == kReplied)
            return take_reply(r, seq, reply, cap, reply_len);
        const std::uint64_t now = now_ns();
        const bool late = now >= deadline;
        const bool gone = e->status.load(Acq) != st;
        if (late || gone) {
            if (abandon(r, seq)) return take_reply(r, seq, reply, cap, reply_len);
            if (gone) {
                set_error("RTPU %d left or died before replying (slot %s)", rtpu,
                          state_name(bp::status_state(e->status.load(Acq))));
                return -EHOSTDOWN;
            }
            set_error("RTPU %d did not reply within %llu ms", rtpu,
                      static_cast<unsigned long long>(timeout_ns / 1000000));
            return -ETIMEDOUT;
        }
        std::uint64_t slice = deadline - now;
        if (slice > std::uint64_t(kSliceNs)) slice = std::uint64_t(kSliceNs);
        CHM_STOP_POINT("xmail.request.wait");
        ipc::wait_word(word, ipc::wait_for(slice).deadline());  // -EINTR (a user signal): keep waiting, bounded
        if (kernel::cancel_owed()) {  // destroyed or its cycle aborted meanwhile: give the request up
            if (abandon(r, seq)) return take_reply(r, seq, reply, cap, reply_len);
            set_error("RTPU %d: request given up: the task is ending", rtpu);
            return -EINTR;
        }
    }
}


void cancel(Pending* p) {
    Record* r = p->r;
    if (!r) return;
    p->r = nullptr;
    kernel::hold_drop(r);
    give_up(r, p->seq);
}

int call(int rtpu, Kind kind, const void* req, std::uint32_t len, void* reply, std::uint32_t cap,
         std::uint32_t* reply_len, std::uint64_t timeout_ns) {
    if (reply_len) *reply_len = 0;
    kernel::CallScope in_call;  // a destroy or abort-cycle meanwhile waits for the return
    Pending p;
    if (int e = post(rtpu, kind, req, len, timeout_ns, &p)) return e;
    CHM_STOP_POINT("xmail.request.posted");  // in flight: the server may be serving or have replied
    return await(&p, reply, cap, reply_len);
}

}  // namespace chm::xmail
