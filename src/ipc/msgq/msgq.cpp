// Message queues: creation, open, close, destroy and the snapshot. A queue
// is a registry entry of kind kKindMsgQueue (like a shared memory segment,
// src/ipc/shm): created directly under the registry lock and the arena's,
// opened by name (the process's slot bit in the entry plus a count per
// process), its memory freed with the last attachment after destroy.
// The handle is the queue's address in this process's mapping.
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstring>

#include "chimera/bp.h"
#include "chimera/msgq.h"
#include "ipc/err/report.hpp"
#include "ipc/msgq/msgq.hpp"
#include "kernel/task/holds.hpp"

using namespace chm::bp;
using namespace chm::ipc::msgq;

namespace {

constexpr auto R = std::memory_order_relaxed;

QueueHeader* queue_of(const Attachment* a, std::uint32_t index) {
    return a->at<QueueHeader>(a->entry(index)->offset.load(R));
}

// A queue whose creator died between publishing the entry and writing the
// header (both under the registry lock) never existed for anyone: remove
// it. With the registry lock held; true when it was removed.
bool drop_stillborn_locked(Attachment* a, int index) {
    if (index < 0) return false;
    std::uint32_t off, size;
    char why[200];
    if (entry_payload(*a, std::uint32_t(index), sizeof(QueueHeader), &off, &size, why, sizeof why)) return false;
    if (queue_of(a, std::uint32_t(index))->magic.load(std::memory_order_acquire) == chm::ipc::msgq::kMagic) return false;
    registry_destroy_locked(*a, std::uint32_t(index), a->token);
    return true;
}

const char* where_text(int where) { return where == CHM_MSGQ_COMMON ? "common memory" : "that RTPU's window"; }

// This process opens queue entry `index` (registry lock held): check its
// payload, geometry and, under its own lock, every index, then keep the
// geometry in the process's record of the entry. 0, kCorrupt (set_error
// names the queue and the field), or lock_queue's -EDEADLK. A broken
// queue opens (so it can be inspected and destroyed); its calls fail.
int open_locked(Attachment* a, std::uint32_t index, const char* fn, const char* name) {
    std::uint32_t off = 0, size = 0;
    char why[240];
    int r = entry_payload(*a, index, sizeof(QueueHeader), &off, &size, why, sizeof why);
    auto* q = a->at<QueueHeader>(off);
    Geo g{};
    if (r == 0) r = read_geometry(q, size, &g, why, sizeof why);
    if (r == 0) {
        r = lock_queue(*a, q, g, a->token);
        if (r == 0) {
            r = validate_locked(q, g, why, sizeof why);
            if (r == 0) q->entry.store(index, R);  // queues created by older builds carry no index
            unlock_queue(q);
        } else if (r == -ENOTRECOVERABLE) {
            q->entry.store(index, R);
            r = 0;
        } else {
            return r;  // lock_queue said why
        }
    }
    if (r) return set_error("%s: message queue \"%s\" (registry[%u]): %s", fn, name, index, why), r;
    Attachment::OpenObject& o = a->objects[index];
    std::memcpy(o.words, &g, sizeof g);
    o.kind = kKindMsgQueue;
    o.offset = off;
    return 0;
}

}  // namespace

extern "C" {

void chm_msgq_attr_init(chm_msgq_attr_t* attr) {
    if (!attr) return;
    attr->order = CHM_MSGQ_FIFO;
    attr->max_msg = 256;
    attr->max_count = 64;
    attr->max_bytes = 0;
    attr->max_waiters = 0;
}

static int msgq_create_impl(const char* name, const chm_msgq_attr_t* attr_in, int where, chm_msgq_t** out) {
    chm::kernel::CallScope in_call;  // a destroy or abort-cycle meanwhile waits for the return
    chm_msgq_attr_t attr;
    if (attr_in) attr = *attr_in;
    else chm_msgq_attr_init(&attr);
    if (!name || !out) return set_error("chm_msgq_create: NULL name or out"), -EINVAL;
    const std::uint32_t order = std::uint32_t(attr.order);
    if (order > kPriority) {
        set_error("chm_msgq_create %s: order %u is not CHM_MSGQ_FIFO, _LIFO or _PRIORITY", name, order);
        return -EINVAL;
    }
    if (attr.max_msg == 0 || attr.max_msg > CHM_MSGQ_MSG_MAX || attr.max_count == 0 ||
        attr.max_count > CHM_MSGQ_COUNT_MAX) {
        set_error("chm_msgq_create %s: max_msg %u (1..%u) or max_count %u (1..%u) out of range", name,
                  attr.max_msg, CHM_MSGQ_MSG_MAX, attr.max_count, CHM_MSGQ_COUNT_MAX);
        return -EINVAL;
    }
    if (attr.max_bytes != 0 && attr.max_bytes < attr.max_msg) {
        set_error("chm_msgq_create %s: max_bytes %u below max_msg %u", name, attr.max_bytes, attr.max_msg);
        return -EINVAL;
    }
    if (attr.max_waiters > CHM_MSGQ_WAITERS_MAX) {
        set_error("chm_msgq_create %s: max_waiters %u above %d", name, attr.max_waiters, CHM_MSGQ_WAITERS_MAX);
        return -EINVAL;
    }
    const std::uint32_t waiters = attr.max_waiters ? attr.max_waiters : kDefaultWaiters;
    const std::uint64_t all = std::uint64_t(attr.max_count) * attr.max_msg;
    const std::uint32_t max_bytes = attr.max_bytes ? attr.max_bytes
                                                   : (all > 0xFFFFFFFFu ? 0xFFFFFFFFu : std::uint32_t(all));
    Attachment* a = need_attachment("chm_msgq_create");
    if (!a) return -ENOTCONN;
    if (where != CHM_MSGQ_COMMON && (where < 0 || std::uint32_t(where) >= a->slots())) {
        set_error("chm_msgq_create %s: where %d is neither CHM_MSGQ_COMMON nor an RTPU 0..%u", name, where,
                  a->slots() - 1);
        return -ECHRNG;
    }
    const std::uint32_t size = queue_size(attr.max_msg, attr.max_count, waiters);
    if (size == 0) {
        set_error("chm_msgq_create %s: %u messages of %u bytes do not fit in a backplane", name,
                  attr.max_count, attr.max_msg);
        return -ENOMEM;
    }
    ensure_recovery_registered();
    int r = lock_registry(a, "chm_msgq_create");
    if (r) return r;
    EntryInfo info{};
    const std::uint32_t at = where == CHM_MSGQ_COMMON ? kWhereCommon : std::uint32_t(where);
    r = registry_create_locked(*a, a->token, kKindMsgQueue, name, size, at, a->slot, &info);
    if (r == -EEXIST && drop_stillborn_locked(a, registry_find_locked(*a, name, kKindMsgQueue)))
        r = registry_create_locked(*a, a->token, kKindMsgQueue, name, size, at, a->slot, &info);
    if (r == 0) {
        auto* q = a->at<QueueHeader>(info.offset);
        q->entry.store(info.index, R);
        queue_init(q, order, attr.max_msg, attr.max_count, max_bytes, waiters);
        Geo g;
        char why[200];
        read_geometry(q, size, &g, why, sizeof why);  // just written: cannot fail
        Attachment::OpenObject& o = a->objects[info.index];
        std::memcpy(o.words, &g, sizeof g);
        o.kind = kKindMsgQueue;
        o.offset = info.offset;
        a->local_refs[info.index] = 1;
        *out = reinterpret_cast<chm_msgq_t*>(q);
    }
    registry_unlock(*a);
    switch (r) {
    case 0: break;
    case -EINVAL: set_error("chm_msgq_create: empty name"); break;
    case -EEXIST: set_error("chm_msgq_create: the name \"%s\" is taken", name); break;
    case -ENAMETOOLONG: set_error("chm_msgq_create: name longer than %u", kNameMax); break;
    case -ENOMEM: set_error("chm_msgq_create %s: no %u free bytes in %s", name, size, where_text(where)); break;
    case -ENOSPC: set_error("chm_msgq_create %s: the registry is full (%u entries)", name, a->geo().registry_capacity); break;
    case -ENOTRECOVERABLE: set_error("chm_msgq_create %s: %s was damaged by a process that died in it", name, where_text(where)); break;
    case -EBADMSG: {  // a corrupt arena: its check said which field
        char why[400];
        std::snprintf(why, sizeof why, "%s", chm_bp_last_error());
        set_error("chm_msgq_create %s: %s", name, why);
        break;
    }
    default: set_error("chm_msgq_create %s: error %d", name, r); break;
    }
    return r;
}

static int msgq_open_impl(const char* name, chm_msgq_t** out) {
    chm::kernel::CallScope in_call;  // a destroy or abort-cycle meanwhile waits for the return
    if (!name || !out) return set_error("chm_msgq_open: NULL name or out"), -EINVAL;
    Attachment* a = need_attachment("chm_msgq_open");
    if (!a) return -ENOTCONN;
    ensure_recovery_registered();
    int r = lock_registry(a, "chm_msgq_open");
    if (r) return r;
    int i = registry_find_locked(*a, name, kKindMsgQueue);
    if (i >= 0) {
        std::uint32_t off, size;
        char why[240];
        // The payload first: the stillborn check reads the queue's magic.
        r = entry_payload(*a, std::uint32_t(i), sizeof(QueueHeader), &off, &size, why, sizeof why);
        if (r) {
            registry_unlock(*a);
            return set_error("chm_msgq_open: message queue \"%s\": %s", name, why), r;
        }
    }
    if (drop_stillborn_locked(a, i)) i = -ENOENT;
    if (i >= 0 && (r = open_locked(a, std::uint32_t(i), "chm_msgq_open", name)) == 0) {
        registry_ref_locked(*a, std::uint32_t(i));
        *out = reinterpret_cast<chm_msgq_t*>(queue_of(a, std::uint32_t(i)));
    }
    registry_unlock(*a);
    if (i < 0) return set_error("chm_msgq_open: no message queue \"%s\"", name), -ENOENT;
    return r;
}

static int msgq_close_impl(chm_msgq_t* q) {
    chm::kernel::CallScope in_call;  // a destroy or abort-cycle meanwhile waits for the return
    Attachment* a = need_attachment("chm_msgq_close");
    if (!a) return -ENOTCONN;
    const char* p = reinterpret_cast<const char*>(q);
    if (!p || p < a->base || p >= a->base + a->size)
        return set_error("chm_msgq_close: %p is not in the backplane", static_cast<void*>(q)), -EINVAL;
    int r = lock_registry(a, "chm_msgq_close");
    if (r) return r;
    r = registry_unref_locked(*a, a->off_of(p), kKindMsgQueue);
    registry_unlock(*a);
    if (r) set_error("chm_msgq_close: %p is not a queue opened by this process", static_cast<void*>(q));
    return r;
}

static int msgq_destroy_impl(const char* name) {
    chm::kernel::CallScope in_call;  // a destroy or abort-cycle meanwhile waits for the return
    if (!name) return set_error("chm_msgq_destroy: NULL name"), -EINVAL;
    Attachment* a = need_attachment("chm_msgq_destroy");
    if (!a) return -ENOTCONN;
    ensure_recovery_registered();
    int r = lock_registry(a, "chm_msgq_destroy");
    if (r) return r;
    const int i = registry_find_locked(*a, name, kKindMsgQueue);
    WakeBuf<CHM_MSGQ_WAITERS_MAX> wakes;
    if (i >= 0) {
        std::uint32_t off = 0, size = 0;
        char why[200];
        Geo g;
        // A corrupt entry or queue is removed from the registry without
        // following anything in it (nobody can be blocked in it: its
        // open fails).
        const bool sound = entry_payload(*a, std::uint32_t(i), sizeof(QueueHeader), &off, &size, why, sizeof why) == 0 &&
                           read_geometry(a->at<QueueHeader>(off), size, &g, why, sizeof why) == 0;
        QueueHeader* q = sound ? a->at<QueueHeader>(off) : nullptr;
        if (q && q->magic.load(std::memory_order_acquire) == chm::ipc::msgq::kMagic) {
            // Blocked callers learn of it now (-EIDRM), not never. A broken
            // queue has no one to wake but is destroyed all the same.
            r = lock_queue(*a, q, g, a->token);
            if (r == 0) {
                lock_mark_dirty(&q->lock);
                q->destroyed.store(1, R);
                grant_all_locked(q, g, &wakes);
                lock_clear_dirty(&q->lock);
                unlock_queue(q);
            } else if (r == -ENOTRECOVERABLE) {
                q->destroyed.store(1, R);
                r = 0;
            }
        }
        if (r == 0) registry_destroy_locked(*a, std::uint32_t(i), a->token);
    }
    registry_unlock(*a);
    wakes.deliver();
    if (i < 0) return set_error("chm_msgq_destroy: no message queue \"%s\"", name), -ENOENT;
    return r;
}

static int msgq_info_impl(chm_msgq_t* h, chm_msgq_info_t* out) {
    Attachment* a = need_attachment("chm_msgq_info");
    if (!a) return -ENOTCONN;
    const char* p = reinterpret_cast<const char*>(h);
    if (!out || !p || p < a->base || std::uint32_t(p - a->base) > a->size - sizeof(QueueHeader))
        return set_error("chm_msgq_info: NULL out or not a queue"), -EINVAL;
    const auto* q = reinterpret_cast<const QueueHeader*>(p);
    const std::uint32_t e = q->entry.load(R);
    if (e >= a->geo().registry_capacity || a->objects[e].offset != a->off_of(p) || a->objects[e].kind != kKindMsgQueue)
        return set_error("chm_msgq_info: %p is not a message queue open in this process", static_cast<const void*>(p)), -EINVAL;
    Geo g;
    std::memcpy(&g, a->objects[e].words, sizeof g);  // the geometry its open checked
    out->attr.order = chm_msgq_order(g.order);
    out->attr.max_msg = g.max_msg;
    out->attr.max_count = g.max_count;
    out->attr.max_bytes = g.max_bytes;
    out->attr.max_waiters = g.max_waiters;
    out->count = q->count.load(R);
    out->bytes = q->bytes.load(R);
    out->receivers_waiting = q->recv_waiting.load(R);
    out->senders_waiting = q->send_waiting.load(R);
    out->sent = q->sent.load(R);
    out->received = q->received.load(R);
    out->broken = int(q->broken.load(R));
    out->destroyed = int(q->destroyed.load(R));
    return 0;
}

}  // extern "C"

// The public calls: each leaves through ipc::leave, which turns a failure
// into an error signal of module "ipc" under global handling
// (ipc/err/report.hpp). Every lock the call took is released by then.
extern "C" {

int chm_msgq_create(const char* name, const chm_msgq_attr_t* attr, int where, chm_msgq_t** out) {
    return chm::ipc::leave(msgq_create_impl(name, attr, where, out), "chm_msgq_create");
}
int chm_msgq_open(const char* name, chm_msgq_t** out) {
    return chm::ipc::leave(msgq_open_impl(name, out), "chm_msgq_open");
}
int chm_msgq_close(chm_msgq_t* q) { return chm::ipc::leave(msgq_close_impl(q), "chm_msgq_close"); }
int chm_msgq_destroy(const char* name) {
    return chm::ipc::leave(msgq_destroy_impl(name), "chm_msgq_destroy");
}
int chm_msgq_info(chm_msgq_t* q, chm_msgq_info_t* out) {
    return chm::ipc::leave(msgq_info_impl(q, out), "chm_msgq_info");
}

}  // extern "C"
