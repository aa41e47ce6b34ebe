// The client side of the host server: requests through express mail to
// backplane slot 0 and the transfer segment (client.hpp).
#include "host/client.hpp"

#include <atomic>
#include <cerrno>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "chimera/bp.h"
#include "chimera/err.h"
#include "chimera/host.h"
#include "chimera/rtpu.h"
#include "chimera/shm.h"
#include "chimera/xfs.h"
#include "ipc/backplane/backplane.hpp"
#include "ipc/xmail/xmail.hpp"
#include "kernel/err/last.hpp"

namespace chm::host {

namespace {

thread_local char t_error[256];

// In ms, 32 bits (m68k has no lock-free 64-bit atomics).
std::atomic<std::uint32_t> g_timeout_ms{std::uint32_t(CHM_HOST_TIMEOUT_DEFAULT_NS / 1000000)};

// The transfer segment: made once, on first use, by whichever task gets
// there first (the others move their data inline meanwhile).
enum : int { kNone = 0, kMaking = 1, kReady = 2, kUnavailable = 3 };
std::atomic<int> g_bulk_state{kNone};
char* g_bulk_base = nullptr;
std::atomic<std::uint32_t> g_bulk_lent{0};  // bit k: buffer k is lent
std::uint32_t g_bulk_attach = 0;             // bp::attach_count() it was made in

bool bulk_ready() {
    bp::Attachment* a = bp::current();
    if (!a) return false;
    int st = g_bulk_state.load(std::memory_order_acquire);
    const bool same = g_bulk_attach == bp::attach_count();  // not a segment of an earlier attachment
    if (st == kMaking || (same && st == kUnavailable)) return false;
    if (same && st == kReady) return true;
    if (!g_bulk_state.compare_exchange_strong(st, kMaking, std::memory_order_acq_rel)) return false;
    g_bulk_lent.store(0, std::memory_order_relaxed);
    // A task with global error handling would take -EEXIST or -ENOMEM as
    // an error signal; here they are outcomes.
    const int global = chm_err_global_get();
    if (global) (void)chm_err_global(0);
    char name[CHM_BP_NAME_MAX + 1];
    bulk_name(name, sizeof name, a->slot);
    void* addr = nullptr;
    const std::size_t want = std::size_t(kBulkSize) * kBulkBuffers;
    int r = chm_shm_create(name, want, CHM_SHM_COMMON, &addr);
    if (r == -EEXIST) {  // left by an earlier process in this slot
        std::size_t size = 0;
        r = chm_shm_attach(name, &addr, &size);
        if (r == 0 && size < want) {
            (void)chm_shm_detach(addr);
            r = -EMSGSIZE;
        }
    }
    if (global) (void)chm_err_global(1);
    g_bulk_attach = bp::attach_count();
    if (r != 0) {
        g_bulk_state.store(kUnavailable, std::memory_order_release);
        return false;
    }
    g_bulk_base = static_cast<char*>(addr);
    g_bulk_state.store(kReady, std::memory_order_release);
    return true;
}

}  // namespace

void set_error(const char* fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    std::vsnprintf(t_error, sizeof t_error, fmt, ap);
    va_end(ap);
    kernel::err_last_set(t_error);  // chm_err_last
}
void clear_error() { t_error[0] = 0; }

std::uint32_t inline_room() {
    bp::Attachment* a = bp::current();
    if (!a) return 0;
    const std::uint32_t rsize = xmail::ring_record_size(*a);
    if (rsize < xmail::kRecordMin) return 0;
    return rsize - std::uint32_t(sizeof(xmail::Record)) - std::uint32_t(sizeof(HostRequest));
}

Bulk bulk_take() {
    if (!bulk_ready()) return {};
    std::uint32_t lent = g_bulk_lent.load(std::memory_order_relaxed);
    for (;;) {
        std::uint32_t k = 0;
        while (k < kBulkBuffers && (lent & (1u << k))) ++k;
        if (k == kBulkBuffers) return {};
        if (g_bulk_lent.compare_exchange_weak(lent, lent | (1u << k), std::memory_order_acquire))
            return {g_bulk_base + std::size_t(k) * kBulkSize, k + 1};
    }
}

void bulk_give(Bulk b) {
    if (b.index) g_bulk_lent.fetch_and(~(1u << (b.index - 1)), std::memory_order_release);
}

int post_request(HostRequest h, const void* text, std::uint32_t text_len, xmail::Pending* p, const char* what,
                 std::uint64_t timeout_ns) {
    t_error[0] = 0;
    if (!bp::current()) return set_error("%s: not attached to a backplane", what), -ENOTCONN;
    if (text_len > inline_room())
        return set_error("%s: %u bytes do not fit one request (%u)", what, text_len, inline_room()), -ENAMETOOLONG;
    h.text_len = text_len;
    // On the stack up to 2 KiB of request (the default ring record is
    // 1 KiB); the heap (the kernel's, safe in a task) beyond.
    char small[2048];
    const std::size_t len = sizeof h + text_len;
    char* buf = len <= sizeof small ? small : static_cast<char*>(std::malloc(len));
    if (!buf) return set_error("%s: no memory for the request", what), -ENOMEM;
    std::memcpy(buf, &h, sizeof h);
    if (text_len) std::memcpy(buf + sizeof h, text, text_len);
    const int r = xmail::post(kServerSlot, xmail::kHost, buf, std::uint32_t(len),
                              timeout_ns ? timeout_ns : chm_host_timeout(), p);
    if (buf != small) std::free(buf);
    if (r < 0) set_error("%s: host server: %s", what, chm_rtpu_last_error());
    return r;
}

int await_request(xmail::Pending* p, void* reply, std::uint32_t cap, std::uint32_t* reply_len, const char* what) {
    t_error[0] = 0;
    if (reply_len) *reply_len = 0;
    // A refusal's reply is the server's reason: read it here when the
    // caller has no room for replies.
    char why[256];
    const bool own = cap < sizeof why;
    std::uint32_t n = 0;
    const int r = xmail::await(p, own ? why : reply, own ? sizeof why - 1 : cap, &n);
    if (r >= 0) {
        if (own && reply && n) std::memcpy(reply, why, n < cap ? n : cap);
        if (reply_len) *reply_len = n;
        return r;
    }
    const char* transport = chm_rtpu_last_error();
    if (*transport) {  // the host server could not be reached
        set_error("%s: host server: %s", what, transport);
    } else {
        char* text = own ? why : static_cast<char*>(reply);
        const std::uint32_t room = own ? sizeof why - 1 : cap;
        const bool has = n > 1 && n <= room && text[n - 1] == 0;
        set_error("%s: %s", what, has ? text : std::strerror(-r));
    }
    return r;
}

int request(HostRequest h, const void* text, std::uint32_t text_len, void* reply, std::uint32_t cap,
            std::uint32_t* reply_len, const char* what, std::uint64_t timeout_ns) {
    if (reply_len) *reply_len = 0;
    xmail::Pending p;
    if (int e = post_request(h, text, text_len, &p, what, timeout_ns)) return e;
    return await_request(&p, reply, cap, reply_len, what);
}

}  // namespace chm::host

extern "C" {

const char* chm_xfs_last_error(void) { return chm::host::t_error; }

void chm_host_timeout_set(uint64_t timeout_ns) {
    const std::uint64_t ns = timeout_ns ? timeout_ns : CHM_HOST_TIMEOUT_DEFAULT_NS;
    const std::uint64_t ms = ns / 1000000 ? ns / 1000000 : 1;
    chm::host::g_timeout_ms.store(ms > UINT32_MAX ? UINT32_MAX : std::uint32_t(ms), std::memory_order_relaxed);
}

uint64_t chm_host_timeout(void) {
    return std::uint64_t(chm::host::g_timeout_ms.load(std::memory_order_relaxed)) * 1000000u;
}

}  // extern "C"
