// Global shared memory: a segment is a registry entry of kind kKindShm
// whose payload is the memory itself. Attach and detach set and clear the
// process's slot bit in the entry (so a dead or departed slot's
// attachments are dropped by recovery or leave) and count attaches per
// process; the data path is the caller's own loads and stores.
#include <cerrno>
#include <cstdint>
#include <cstdio>

#include "chimera/bp.h"
#include "chimera/shm.h"
#include "ipc/backplane/backplane.hpp"
#include "ipc/backplane/stop_point.hpp"
#include "ipc/err/report.hpp"
#include "kernel/task/holds.hpp"

using namespace chm::bp;

extern "C" {

static int shm_create_impl(const char* name, size_t size, int where, void** out) {
    if (!name || !out || size == 0 || std::uint64_t(size) >= (std::uint64_t(1) << 32) - 4096) {
        set_error("chm_shm_create: NULL name or out, or size %zu out of range", size);
        return -EINVAL;
    }
    Attachment* a = need_attachment();
    if (!a) return -ENOTCONN;
    if (where != CHM_SHM_COMMON && (where < 0 || std::uint32_t(where) >= a->slots())) {
        set_error("chm_shm_create %s: where %d is neither CHM_SHM_COMMON nor an RTPU 0..%u", name, where, a->slots() - 1);
        return -ECHRNG;
    }
    chm::kernel::CallScope in_call;  // a destroy or abort-cycle meanwhile waits for the return
    int r = lock_registry(a);
    if (r) return r;
    EntryInfo info{};
    r = registry_create_locked(*a, a->token, kKindShm, name, std::uint32_t(size),
                               where == CHM_SHM_COMMON ? kWhereCommon : std::uint32_t(where), a->slot, &info);
    if (r == 0) a->local_refs[info.index] = 1;
    registry_unlock(*a);
    switch (r) {
    case 0: *out = a->base + info.offset; break;
    case -EEXIST: set_error("chm_shm_create: the name \"%s\" is taken", name); break;
    case -ENAMETOOLONG: set_error("chm_shm_create: name longer than %u", kNameMax); break;
    case -ENOMEM: set_error("chm_shm_create %s: no %zu free bytes in %s", name, size, where == CHM_SHM_COMMON ? "common memory" : "that RTPU's window"); break;
    case -ENOSPC: set_error("chm_shm_create %s: the registry is full (%u entries)", name, a->geo().registry_capacity); break;
    case -ENOTRECOVERABLE: set_error("chm_shm_create %s: that memory was damaged by a process that died in it", name); break;
    case -EBADMSG: {  // a corrupt arena: its check said which field
        char why[400];
        std::snprintf(why, sizeof why, "%s", chm_bp_last_error());
        set_error("chm_shm_create %s: %s", name, why);
        break;
    }
    default: set_error("chm_shm_create %s: error %d", name, r); break;
    }
    return r;
}

static int shm_attach_impl(const char* name, void** out, size_t* size) {
    if (!name || !out) return set_error("chm_shm_attach: NULL name or out"), -EINVAL;
    Attachment* a = need_attachment();
    if (!a) return -ENOTCONN;
    chm::kernel::CallScope in_call;
    int r = lock_registry(a);
    if (r) return r;
    const int i = registry_find_locked(*a, name, kKindShm);
    CHM_STOP_POINT("shm.attach.locked");
    char why[200];
    if (i >= 0) {
        // The segment is handed out as plain memory: its offset and size
        // must describe an allocated block of its arena (no 32-bit wrap).
        std::uint32_t off, bytes;
        r = entry_payload(*a, std::uint32_t(i), 1, &off, &bytes, why, sizeof why);
        if (r == 0) {
            registry_ref_locked(*a, std::uint32_t(i));
            *out = a->base + off;
            if (size) *size = bytes;
        }
    }
    registry_unlock(*a);
    if (i < 0) return set_error("chm_shm_attach: no shared memory segment \"%s\"", name), -ENOENT;
    if (r) set_error("chm_shm_attach: segment \"%s\": %s", name, why);
    return r;
}

static int shm_detach_impl(void* addr) {
    chm::kernel::CallScope in_call;  // a destroy or abort-cycle meanwhile waits for the return
    Attachment* a = need_attachment();
    if (!a) return -ENOTCONN;
    const char* p = static_cast<const char*>(addr);
    if (!p || p < a->base || p >= a->base + a->size)
        return set_error("chm_shm_detach: %p is not in the backplane", addr), -EINVAL;
    int r = lock_registry(a);
    if (r) return r;
    r = registry_unref_locked(*a, a->off_of(p), kKindShm);
    registry_unlock(*a);
    if (r) set_error("chm_shm_detach: %p is not a segment attached by this process", addr);
    return r;
}

static int shm_destroy_impl(const char* name) {
    chm::kernel::CallScope in_call;  // a destroy or abort-cycle meanwhile waits for the return
    if (!name) return set_error("chm_shm_destroy: NULL name"), -EINVAL;
    Attachment* a = need_attachment();
    if (!a) return -ENOTCONN;
    int r = lock_registry(a);
    if (r) return r;
    const int i = registry_find_locked(*a, name, kKindShm);
    if (i >= 0) registry_destroy_locked(*a, std::uint32_t(i), a->token);
    registry_unlock(*a);
    if (i < 0) return set_error("chm_shm_destroy: no shared memory segment \"%s\"", name), -ENOENT;
    return 0;
}

}  // extern "C"

// The public calls: each leaves through ipc::leave, which turns a failure
// into an error signal of module "ipc" under global handling
// (ipc/err/report.hpp). Every lock the call took is released by then.
extern "C" {

int chm_shm_create(const char* name, size_t size, int where, void** out) {
    return chm::ipc::leave(shm_create_impl(name, size, where, out), "chm_shm_create");
}
int chm_shm_attach(const char* name, void** out, size_t* size) {
    return chm::ipc::leave(shm_attach_impl(name, out, size), "chm_shm_attach");
}
int chm_shm_detach(void* addr) { return chm::ipc::leave(shm_detach_impl(addr), "chm_shm_detach"); }
int chm_shm_destroy(const char* name) {
    return chm::ipc::leave(shm_destroy_impl(name), "chm_shm_destroy");
}

}  // extern "C"
