// msgq_stream_24b_xrtpu: cross-RTPU streaming throughput. A sender task on
// RTPU 1 (this process, first CPU) sends 24-byte messages through a queue in
// RTPU 2's window to a receiver task on RTPU 2 (a forked process running its
// own kernel, second CPU); the sender waits only when the queue (64 slots)
// is full, the receiver only when it is empty. A run sends n messages, the
// last one marked; the receiver answers the mark on a second queue, and the
// run ends when the sender has that answer: ns per message = run / n. The
// peer, peer_bipc_mq_stream_24b_xcore (peers/boost_mq.cpp), does the same
// between two processes pinned the same way with Boost message_queue.
// msgq_stream_64k_xrtpu: the same with 64 KiB messages (8 slots), beside
// peer_bipc_mq_stream_64k_xcore.
//
// msgq_wake_rt2 (and msgq_wake_rt2_vs_floor): the 24-byte round trip that
// wakes a receiver sleeping on another RTPU, kernels on both ends.
#include <cstdint>
#include <cstring>
#include <algorithm>
#include <functional>
#include <vector>
#include <string>

#include "../harness.hpp"
#include "chimera/msgq.h"
#include "rtpu.hpp"

namespace chm::bench {
namespace {

constexpr std::size_t kMsg = 24;
constexpr std::uint32_t kSlots = 64;

chm_msgq_t* make_queue(const char* name, int where, std::uint32_t count, std::size_t msg = kMsg) {
    chm_msgq_attr_t a;
    chm_msgq_attr_init(&a);
    a.max_msg = std::uint32_t(msg);
    a.max_count = count;
    chm_msgq_t* q = nullptr;
    if (const int r = chm_msgq_create(name, &a, where, &q)) ipcb::fail_bp("chm_msgq_create", r);
    return q;
}

void check_q(int r, const char* what) {
    if (r < 0) ipcb::fail_bp(what, r);
}

// The stream's message size, for the receiver in the forked RTPU (set
// before the fork, so the child has it).
std::size_t g_stream_msg = kMsg;

void stream(Session& s, const char* row, std::size_t msg, std::uint32_t slots) {
    s.need_cpus(2);
    Session::pin(s.cpu(0));
    // RTPU 2's window holds the data queue: slots x msg bytes and headers.
    ipcb::BackplaneFile f("stream", 10, std::uint32_t(std::max<std::size_t>(256 * 1024, 2 * slots * msg)));
    ipcb::Joined me(f.path, 1);
    chm_msgq_t* data = make_queue("data", 2, slots, msg);  // in the receiver's window
    chm_msgq_t* ack = make_queue("ack", 1, 4);              // in the sender's
    g_stream_msg = msg;
    auto child = ipcb::rtpu_child(s.cpu(1), f.path, 2, 0, ipcb::child_limit(s), [](ipcb::Kernel& k) {
        static std::function<void()> body;
        body = [] {
            chm_msgq_t *d = nullptr, *a = nullptr;
            check_q(chm_msgq_open("data", &d), "chm_msgq_open data");
            check_q(chm_msgq_open("ack", &a), "chm_msgq_open ack");
            std::vector<char> buf(g_stream_msg);
            for (;;) {
                check_q(chm_msgq_receive(d, buf.data(), buf.size(), nullptr), "chm_msgq_receive");
                if (buf[0] == 1) check_q(chm_msgq_send(a, 1, 0, buf.data(), kMsg), "chm_msgq_send ack");
            }
        };
        k.spawn(&body, 10, "receiver");
    });
    ipcb::wait_rtpus_running({2});
    ipcb::Kernel k(1, 0);
    std::function<void()> body = [&] {
        s.time_custom(
            row,
            "cross core: a sender task on RTPU 1 (this process) pinned " + s.cpu_name(0) +
                ", a receiver task on RTPU 2 (a forked process, its own kernel) pinned " +
                s.cpu_name(1) + ", default config (MUF, 1 ms quantum), idle_poll_ns 0 (the RTPU options of the "
                "backplane rows); queue of " + std::to_string(slots) + " slots of " + std::to_string(msg) +
                " bytes in RTPU 2's window, blocking chm_msgq_send / chm_msgq_receive of " + std::to_string(msg) +
                "-byte messages; per message, a run's last message answered on a second queue",
            [&](std::uint64_t n) {
                std::vector<char> buf(msg, 0);
                char reply[kMsg];
                const std::uint64_t t0 = mono_ns();
                for (std::uint64_t i = 0; i < n; ++i) {
                    buf[0] = i + 1 == n ? 1 : 0;
                    check_q(chm_msgq_send(data, 1, 0, buf.data(), msg), "chm_msgq_send");
                }
                check_q(chm_msgq_receive(ack, reply, sizeof reply, nullptr), "chm_msgq_receive ack");
                return double(mono_ns() - t0);
            });
    };
    k.spawn(&body, 10, "sender");
    k.run();
}

void msgq_stream(Session& s) { stream(s, "msgq_stream_24b_xrtpu", kMsg, kSlots); }
CHM_BENCH_MEASUREMENT(msgq_stream, "msgq_stream_24b_xrtpu");

// 64 KiB messages: 8 slots, as the peer's queue (peer_bipc_mq_stream_64k_xcore).
void msgq_stream_64k(Session& s) { stream(s, "msgq_stream_64k_xrtpu", 64 * 1024, 8); }
CHM_BENCH_MEASUREMENT(msgq_stream_64k, "msgq_stream_64k_xrtpu");

// msgq_wake_rt2 through kernels on both ends: a task on RTPU 1 sends a
// 24-byte message to a task on RTPU 2 sleeping in receive (queues of 8 in
// common memory), which answers on a second queue; both RTPUs on one core,
// as the peer's two processes. RT/2.
void msgq_wake_kernels(Session& s) {
    Session::pin(s.cpu(0));
    ipcb::BackplaneFile f("wake");
    ipcb::Joined me(f.path, 1);
    chm_msgq_t* down = make_queue("down", CHM_MSGQ_COMMON, 8);
    chm_msgq_t* up = make_queue("up", CHM_MSGQ_COMMON, 8);
    auto child = ipcb::rtpu_child(s.cpu(0), f.path, 2, 0, ipcb::child_limit(s), [](ipcb::Kernel& k) {
        static std::function<void()> body;
        body = [] {
            chm_msgq_t *d = nullptr, *u = nullptr;
            check_q(chm_msgq_open("down", &d), "chm_msgq_open down");
            check_q(chm_msgq_open("up", &u), "chm_msgq_open up");
            char buf[kMsg];
            for (;;) {
                check_q(chm_msgq_receive(d, buf, sizeof buf, nullptr), "chm_msgq_receive");
                check_q(chm_msgq_send(u, 2, 0, buf, kMsg), "chm_msgq_send");
            }
        };
        k.spawn(&body, 10, "echo");
    });
    ipcb::wait_rtpus_running({2});
    ipcb::Kernel k(1, 0);
    std::function<void()> body = [&] {
        const std::string config =
            "same core (" + s.cpu_name(0) + "): a task on RTPU 1 (this process) and a task on RTPU "
            "2 (a forked process, its own kernel), default config (MUF, 1 ms quantum), idle_poll_ns 0 (an idle RTPU "
            "sleeps on its doorbell's futex at once); queues of 8 24-byte slots in common memory, "
            "blocking chm_msgq_send / chm_msgq_receive; RT/2";
        const Stats st = s.time_ops(
            "msgq_wake_rt2", config,
            [&](std::uint64_t n) {
                char buf[kMsg];
                std::memset(buf, 7, sizeof buf);
                for (std::uint64_t i = 0; i < n; ++i) {
                    check_q(chm_msgq_send(down, 1, 0, buf, kMsg), "chm_msgq_send");
                    check_q(chm_msgq_receive(up, buf, sizeof buf, nullptr), "chm_msgq_receive");
                }
            },
            2);
        s.emit("msgq_wake_rt2_vs_floor", "msgq_wake_rt2's runs: " + config, st.median, st.min, st.max);
    };
    k.spawn(&body, 10, "bench");
    k.run();
}
CHM_BENCH_MEASUREMENT(msgq_wake_kernels, "msgq_wake_rt2", "msgq_wake_rt2_vs_floor");

}  // namespace
}  // namespace chm::bench
