// libFuzzer harness: message framing. Three queues (FIFO, LIFO, priority
// order; one with a payload-byte limit) in a private backplane this process
// stays attached to; the input is a program of try-sends and
// try-receives. Every message comes back with its type, priority, sender,
// length and bytes, in the order the queue promises (a model of each
// queue says which), a send that does not fit is refused with -EMSGSIZE
// or -EAGAIN, a receive into a short buffer with -EMSGSIZE (the message
// stays queued). After each input the queues are drained and must pass
// the strict checker.
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <string>

#include "chimera/bp.h"
#include "chimera/msgq.h"
#include "ipc/backplane/backplane.hpp"
#include "ipc/msgq/msgq.hpp"
#include "seed_image.hpp"

namespace {

constexpr std::uint32_t kMaxMsg = 40, kCount = 6;

struct Msg {
    std::uint32_t type, prio, len, stamp;
};

struct Q {
    chm_msgq_t* h;
    chm_msgq_order order;
    std::uint32_t max_bytes;
    std::deque<Msg> model;  // arrival order
    std::uint32_t bytes = 0;
};
Q g_q[3];
std::uint32_t g_stamp = 0;

void fill(char* buf, std::uint32_t len, std::uint32_t stamp) {
    for (std::uint32_t i = 0; i < len; ++i) buf[i] = char(stamp * 31 + i);
}

// Which model entry the queue must hand out next.
std::size_t next_of(const Q& q) {
    if (q.order == CHM_MSGQ_FIFO) return 0;
    if (q.order == CHM_MSGQ_LIFO) return q.model.size() - 1;
    std::size_t best = 0;
    for (std::size_t i = 1; i < q.model.size(); ++i)
        if (q.model[i].prio > q.model[best].prio) best = i;
    return best;
}

void fail(const char* what) {
    std::fprintf(stderr, "fuzz_msgq: %s (%s)\n", what, chm_bp_last_error());
    std::abort();
}

void receive(Q& q, std::uint32_t cap) {
    char buf[kMaxMsg + 8];
    chm_msgq_msg_info_t info{};
    const int r = chm_msgq_try_receive(q.h, buf, cap, &info);
    if (q.model.empty()) {
        if (r != -EAGAIN) fail("receive from an empty queue");
        return;
    }
    const std::size_t k = next_of(q);
    const Msg m = q.model[k];
    if (info.type != m.type || info.prio != m.prio || info.len != m.len || info.sender != chm_bp_self())
        fail("message info differs");
    if (m.len > cap) {
        if (r != -EMSGSIZE) fail("short buffer not refused");
        return;
    }
    if (r != int(m.len)) fail("wrong length");
    char want[kMaxMsg];
    fill(want, m.len, m.stamp);
    if (std::memcmp(buf, want, m.len) != 0) fail("payload differs");
    q.model.erase(q.model.begin() + std::ptrdiff_t(k));
    q.bytes -= m.len;
}

void send(Q& q, std::uint32_t type, std::uint32_t prio, std::uint32_t len) {
    char buf[256];
    const std::uint32_t stamp = ++g_stamp;
    fill(buf, len, stamp);
    const int r = chm_msgq_try_send(q.h, type, prio, buf, len);
    if (prio > CHM_MSGQ_PRIO_MAX) {
        if (r != -EINVAL) fail("priority above 31 accepted");
        return;
    }
    if (len > kMaxMsg || len > q.max_bytes) {
        if (r != -EMSGSIZE) fail("oversized message accepted");
        return;
    }
    if (q.model.size() == kCount || q.bytes + len > q.max_bytes) {
        if (r != -EAGAIN) fail("full queue accepted a message");
        return;
    }
    if (r != 0) fail("send refused");
    q.model.push_back(Msg{type, prio, len, stamp});
    q.bytes += len;
}

void lines(void* ctx, const char* line) { static_cast<std::string*>(ctx)->append(line).append("\n"); }

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
    const std::string dir = chm::fuzz::private_dir("chm-fuzz-msgq-");
    const std::string path = dir + "/q.bp";
    chm_bp_config_t c;
    chm_bp_config_init(&c);
    c.rtpu_slots = 2;
    c.common_size = 65536;
    c.registry_capacity = 4;
    if (chm_bp_create(path.c_str(), &c) || chm_bp_attach_host(path.c_str(), "fuzz", nullptr)) fail("backplane");
    ::unlink(path.c_str());  // the mapping stays; nothing is left behind
    ::rmdir(dir.c_str());
    const chm_msgq_order orders[3] = {CHM_MSGQ_FIFO, CHM_MSGQ_LIFO, CHM_MSGQ_PRIORITY};
    const std::uint32_t limits[3] = {kMaxMsg * kCount, kMaxMsg * kCount, 100};
    const char* names[3] = {"fifo", "lifo", "prio"};
    for (int i = 0; i < 3; ++i) {
        chm_msgq_attr_t a;
        chm_msgq_attr_init(&a);
        a.order = orders[i];
        a.max_msg = kMaxMsg;
        a.max_count = kCount;
        a.max_bytes = i == 2 ? limits[i] : 0;
        if (chm_msgq_create(names[i], &a, CHM_MSGQ_COMMON, &g_q[i].h)) fail("create");
        g_q[i].order = orders[i];
        g_q[i].max_bytes = limits[i];
    }
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    // Each operation: op byte (bits 0-1 queue, bits 2-3 what), then for a
    // send its priority byte and length byte, for a receive its buffer size.
    for (std::size_t k = 0; k < size;) {
        const std::uint8_t op = data[k++];
        Q& q = g_q[(op & 3) % 3];
        switch ((op >> 2) & 3) {
        case 0:
        case 1: {
            if (k + 2 > size) break;
            const std::uint32_t prio = data[k] & 0x3F, len = data[k + 1];
            k += 2;
            send(q, op >> 4, prio, len);
            break;
        }
        case 2:
            receive(q, kMaxMsg);
            break;
        case 3:
            if (k + 1 > size) break;
            receive(q, data[k++] % (kMaxMsg + 1));
            break;
        }
    }
    for (Q& q : g_q) {
        while (!q.model.empty()) receive(q, kMaxMsg);
        receive(q, kMaxMsg);  // and it is empty
        std::string out;
        chm::bp::Report r;
        r.emit = lines;
        r.ctx = &out;
        auto* h = reinterpret_cast<chm::ipc::msgq::QueueHeader*>(q.h);
        chm::ipc::msgq::check_queue(*chm::bp::current(), h, h->total_size, "queue", r);
        if (r.problems) {
            std::fprintf(stderr, "%s", out.c_str());
            std::abort();
        }
    }
    return 0;
}
