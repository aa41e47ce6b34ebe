// msgq_oneway_polling_xrtpu: a 24-byte message from a task on RTPU 1 (this
// process, first CPU) to a task on RTPU 2 (a forked process with its own
// kernel, second CPU) whose receive polls: both RTPUs run with idle_poll_ns,
// so a task whose chm_msgq_receive must wait, with nothing else to run on
// its RTPU, spins on its grant word before it parks, and a send that finds
// it waiting stores the message and the grant and rings nothing. The
// receiver answers on a second queue in RTPU 1's window; one-way = RT/2 of
// the ping-pong.
//
// Its floor, peer_cacheline_pingpong_msgq_rtpus: the same two tasks pass
// one cache line in common memory, spinning, measured run by run in turn
// with it (the host moves its vCPUs between placements whose line transfer
// differs several-fold, sometimes within a run: a floor measured at
// another moment would be judged by the wrong one). PERF target: one-way
// <= 3 x that floor.
#include <atomic>
#include <cstdint>
#include <cstring>
#include <functional>
#include <new>
#include <string>

#include "../harness.hpp"
#include "../peers/cacheline.hpp"
#include "chimera/msgq.h"
#include "chimera/shm.h"
#include "rtpu.hpp"

namespace chm::bench {
namespace {

constexpr std::size_t kMsg = 24;
constexpr std::uint64_t kPollNs = 100'000;  // as rsem_handoff_polling

using Floor = TaskLineFloor;  // ../peers/cacheline.hpp
Floor* floor_in(void* segment) { return task_line_floor_in(segment); }

void check_q(int r, const char* what) {
    if (r < 0) ipcb::fail_bp(what, r);
}

chm_msgq_t* make_queue(const char* name, int where) {
    chm_msgq_attr_t a;
    chm_msgq_attr_init(&a);
    a.max_msg = kMsg;
    a.max_count = 8;
    chm_msgq_t* q = nullptr;
    if (const int r = chm_msgq_create(name, &a, where, &q)) ipcb::fail_bp("chm_msgq_create", r);
    return q;
}

// The partner's loop (RTPU 2): every message is answered; one sent with
// pass_line set first makes it answer the line until kPingStop.
void partner() {
    chm_msgq_t *down = nullptr, *up = nullptr;
    void* seg = nullptr;
    std::size_t size = 0;
    check_q(chm_msgq_open("down", &down), "chm_msgq_open down");
    check_q(chm_msgq_open("up", &up), "chm_msgq_open up");
    check_q(chm_shm_attach("msgq.floor", &seg, &size), "chm_shm_attach msgq.floor");
    Floor& fl = *floor_in(seg);
    char buf[kMsg];
    for (;;) {
        check_q(chm_msgq_receive(down, buf, sizeof buf, nullptr), "chm_msgq_receive");
        if (fl.pass_line.load(std::memory_order_relaxed)) answer_pings(fl.line);
        check_q(chm_msgq_send(up, 2, 0, buf, kMsg), "chm_msgq_send");
    }
}

void msgq_polling_row(Session& s) {
    s.need_cpus(2);
    Session::pin(s.cpu(0));
    ipcb::BackplaneFile f("msgqpoll");
    ipcb::Joined me(f.path, 1);
    chm_msgq_t* down = make_queue("down", 2);  // in the receiver's window
    chm_msgq_t* up = make_queue("up", 1);      // in ours
    void* segment = nullptr;
    if (const int r = chm_shm_create("msgq.floor", sizeof(Floor) + 64, CHM_SHM_COMMON, &segment))
        ipcb::fail_bp("chm_shm_create msgq.floor", r);
    Floor& fl = *new (floor_in(segment)) Floor;
    auto child = ipcb::rtpu_child(s.cpu(1), f.path, 2, kPollNs, ipcb::child_limit(s), [](ipcb::Kernel& k) {
        static std::function<void()> body;
        body = partner;
        k.spawn(&body, 10, "partner");
    });
    ipcb::wait_rtpus_running({2});
    ipcb::Kernel k(1, kPollNs);
    std::function<void()> body = [&] {
        char buf[kMsg];
        std::memset(buf, 7, sizeof buf);
        const auto pingpong = [&](std::uint64_t n) {
            const std::uint64_t t0 = mono_ns();
            for (std::uint64_t i = 0; i < n; ++i) {
                check_q(chm_msgq_send(down, 1, 0, buf, kMsg), "chm_msgq_send");
                check_q(chm_msgq_receive(up, buf, sizeof buf, nullptr), "chm_msgq_receive");
            }
            return double(mono_ns() - t0);
        };
        // The floor: one message switches the partner to the line, n round
        // trips of the line, the stop, and its answer.
        const auto line = [&](std::uint64_t n) {
            fl.line.seq.store(0, std::memory_order_relaxed);
            fl.pass_line.store(1, std::memory_order_relaxed);
            check_q(chm_msgq_send(down, 1, 0, buf, kMsg), "chm_msgq_send");  // publishes both stores
            const double ns = send_pings(fl.line, n);
            fl.line.seq.store(kPingStop, std::memory_order_release);
            check_q(chm_msgq_receive(up, buf, sizeof buf, nullptr), "chm_msgq_receive");
            fl.pass_line.store(0, std::memory_order_relaxed);
            return ns;
        };
        const auto [msg, floor] = s.measure_interleaved(pingpong, line, 2);
        const std::string row = "msgq_oneway_polling_xrtpu";
        s.emit(row,
               "cross core: a task on RTPU 1 (this process) pinned " + s.cpu_name(0) +
                   ", a task on RTPU 2 (a forked process, its own kernel) pinned " + s.cpu_name(1) +
                   ", default config (MUF, 1 ms quantum), idle_poll_ns " + std::to_string(kPollNs / 1000) +
                   " us on both (a task whose receive must wait, with nothing else to run on its RTPU, "
                   "spins on its grant word that long before it parks: a send stores the message and "
                   "the grant and rings nothing); queues of 8 24-byte slots, each in its receiver's "
                   "window; blocking chm_msgq_send / chm_msgq_receive; one-way = RT/2 of the ping-pong; "
                   "median of " + std::to_string(msg.runs) + " runs x " + std::to_string(msg.iters_per_run) +
                   " iterations, each run followed by one of peer_cacheline_pingpong_msgq_rtpus",
               msg.median, msg.min, msg.max);
        s.emit("peer_cacheline_pingpong_msgq_rtpus",
               "the two tasks of " + row + " (RTPU 1 pinned " + s.cpu_name(0) + ", RTPU 2 pinned " +
                   s.cpu_name(1) + ") pass one cache line in common memory, spinning; RT/2; each run "
                   "follows one of " + row,
               floor.median, floor.min, floor.max);
    };
    k.spawn(&body, 10, "bench");
    k.run();
}
CHM_BENCH_MEASUREMENT(msgq_polling_row, "msgq_oneway_polling_xrtpu", "peer_cacheline_pingpong_msgq_rtpus");

}  // namespace
}  // namespace chm::bench
