// Cost against the number of RTPUs (1 to 8): the data of
// docs/bench/scaling_rtpus.png and the row rsem_handoff_8rtpus_over_2.
// Two questions a user adding RTPUs to a machine asks:
//
//  rsem_handoff_rt2   Does communication between two RTPUs get slower when
//                     more RTPUs run? RT/2 of a remote semaphore ping-pong
//                     between a task on RTPU 1 (this process, cpu A) and one
//                     on RTPU 2 (cpu B), sleeping when idle, while RTPUs
//                     3..N run their kernels idle (unpinned). N = 1: the two
//                     tasks on RTPU 1 itself.
//  msgq_fan_in        How much can one queue take from N-1 producers? RTPUs
//                     2..N (unpinned) each run a task sending 24-byte
//                     messages as fast as the queue takes them (blocking
//                     send, queue of 64 in RTPU 1's window); a task on RTPU 1
//                     (cpu A) receives: ns per message received. N = 1: the
//                     sender is a lower-priority task on RTPU 1.
//
// On a 2-core machine more than two busy RTPUs share the cores: the
// fan-in curve shows that cost (wake-ups, time slices), not a backplane
// limit; the hand-off curve shows what idle RTPUs cost the others.
#include <cstdint>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "../harness.hpp"
#include "../kernel/kbench.hpp"  // kb::fmt_ns
#include "chimera/bp.h"
#include "chimera/msgq.h"
#include "chimera/rsem.h"
#include "chimera/shm.h"
#include "rtpu.hpp"
#include "series.hpp"

namespace chm::bench {
namespace {

constexpr int kMaxRtpus = 8;
constexpr std::size_t kMsg = 24;

void ok(int r, const char* what) {
    if (r != 0) ipcb::fail_bp(what, r);
}

using Children = std::vector<std::unique_ptr<Child>>;

// RTPUs first..last in forked children, unpinned, each with the tasks
// `tasks` spawns (none: an idle RTPU, only its guard).
void start_children(Session& s, const std::string& path, int first, int last, int cpu_of_first,
                    const std::function<void(ipcb::Kernel&)>& tasks, Children* out) {
    std::vector<int> slots;
    for (int n = first; n <= last; ++n) {
        out->push_back(ipcb::rtpu_child(n == first ? cpu_of_first : -1, path, n, 0, ipcb::child_limit(s), tasks));
        slots.push_back(n);
    }
    if (!slots.empty()) ipcb::wait_rtpus_running(slots);
}

Stats handoff(Session& s, int rtpus) {
    ipcb::BackplaneFile f("scale", kMaxRtpus + 2);
    ipcb::Joined me(f.path, 1);
    chm_rsem_t *ping = nullptr, *pong = nullptr;
    ok(chm_rsem_create("ping", CHM_SEM_COUNTING, 0, CHM_SHM_COMMON, &ping), "chm_rsem_create");
    ok(chm_rsem_create("pong", CHM_SEM_COUNTING, 0, CHM_SHM_COMMON, &pong), "chm_rsem_create");
    Children kids;
    static std::function<void()> partner;  // in a child: outlives its kernel
    partner = [] {
        chm_rsem_t *pi = nullptr, *po = nullptr;
        ok(chm_rsem_open("ping", &pi), "chm_rsem_open");
        ok(chm_rsem_open("pong", &po), "chm_rsem_open");
        for (;;) {
            ok(chm_rsem_p(pi), "chm_rsem_p");
            ok(chm_rsem_v(po), "chm_rsem_v");
        }
    };
    if (rtpus >= 2) {
        start_children(s, f.path, 2, 2, s.cpu(1), [](ipcb::Kernel& k) { k.spawn(&partner, 10, "partner"); }, &kids);
        start_children(s, f.path, 3, rtpus, -1, [](ipcb::Kernel&) {}, &kids);
    }
    Stats st;
    ipcb::Kernel k(1, 0);
    std::function<void()> body = [&] {
        st = s.measure([&](std::uint64_t n) {
            const std::uint64_t t0 = mono_ns();
            for (std::uint64_t i = 0; i < n; ++i) {
                ok(chm_rsem_v(ping), "chm_rsem_v");
                ok(chm_rsem_p(pong), "chm_rsem_p");
            }
            return double(mono_ns() - t0);
        }, 2);
    };
    std::function<void()> local_partner = [&] {
        // N = 1: the partner on this RTPU; it ends when the driver does.
        for (;;) {
            ok(chm_rsem_p(ping), "chm_rsem_p");
            ok(chm_rsem_v(pong), "chm_rsem_v");
        }
    };
    k.spawn(&body, 10, "bench");
    if (rtpus == 1) k.spawn_endless(&local_partner, 10, "partner");
    k.run();
    return st;
}

Stats fan_in(Session& s, int rtpus) {
    ipcb::BackplaneFile f("fanin", kMaxRtpus + 2);
    ipcb::Joined me(f.path, 1);
    chm_msgq_attr_t a;
    chm_msgq_attr_init(&a);
    a.max_msg = kMsg;
    a.max_count = 64;
    chm_msgq_t* q = nullptr;
    ok(chm_msgq_create("sink", &a, 1, &q), "chm_msgq_create");
    static std::function<void()> sender;
    sender = [] {
        chm_msgq_t* sq = nullptr;
        ok(chm_msgq_open("sink", &sq), "chm_msgq_open");
        char m[kMsg] = {1};
        for (;;) ok(chm_msgq_send(sq, 1, 0, m, kMsg), "chm_msgq_send");
    };
    Children kids;
    if (rtpus >= 2) start_children(s, f.path, 2, rtpus, -1, [](ipcb::Kernel& k) { k.spawn(&sender, 10, "sender"); }, &kids);
    Stats st;
    ipcb::Kernel k(1, 0);
    std::function<void()> body = [&] {
        char m[kMsg];
        st = s.measure([&](std::uint64_t n) {
            const std::uint64_t t0 = mono_ns();
            for (std::uint64_t i = 0; i < n; ++i)
                if (chm_msgq_receive(q, m, sizeof m, nullptr) != int(kMsg)) throw std::runtime_error("chm_msgq_receive");
            return double(mono_ns() - t0);
        });
    };
    k.spawn(&body, 10, "receiver");
    if (rtpus == 1) k.spawn_endless(&sender, 5, "sender");
    k.run();
    return st;
}

void rtpu_scaling(Session& s) {
    s.need_cpus(2);
    Session::pin(s.cpu(0));
    ipcb::Series hand, fan;
    std::vector<double> xs;
    // Quick mode: the ends and the middle only (each N forks its RTPUs twice).
    const std::vector<int> counts = s.quick() ? std::vector<int>{1, 2, 4, 8}
                                              : std::vector<int>{1, 2, 3, 4, 5, 6, 7, 8};
    double at2 = kNull, at8 = kNull;
    for (const int n : counts) {
        xs.push_back(n);
        const Stats h = handoff(s, n);
        hand.add(h);
        if (n == 2) at2 = h.median;
        if (n == kMaxRtpus) at8 = h.median;
        fan.add(fan_in(s, n));
    }
    const std::string cfg = "RTPU 1 = this process pinned " + s.cpu_name(0) + ", RTPU 2 pinned " + s.cpu_name(1) +
                            " in the hand-off, every other RTPU a forked process, unpinned; default config (MUF, 1 ms quantum), "
                            "idle_poll_ns 0 (sleeping), remote semaphores in common memory, the fan-in queue "
                            "(64 x 24 B) in RTPU 1's window";
    s.write_data("scaling_rtpus", ipcb::series_json("rtpus", xs, "ops",
                                                    {{"rsem_handoff_rt2", hand}, {"msgq_fan_in", fan}},
                                                    "\"config\": \"" + cfg + "\""));
    std::string ns_list;
    for (std::size_t i = 0; i < xs.size(); ++i) {
        if (i) ns_list += ',';
        ns_list += std::to_string(counts[i]);
    }
    std::string detail = "hand-off RT/2 for N = " + ns_list + ":";
    for (std::size_t i = 0; i < xs.size(); ++i) detail += (i ? ", " : " ") + kb::fmt_ns(hand.median[i]);
    detail += "; one queue fed by N-1 sender RTPUs, time per message:";
    for (std::size_t i = 0; i < xs.size(); ++i) detail += (i ? ", " : " ") + kb::fmt_ns(fan.median[i]);
    s.emit("rsem_handoff_8rtpus_over_2",
           cfg + "; value = remote semaphore hand-off RT/2 between RTPUs 1 and 2 (cross core) with 8 RTPUs "
                 "running (6 idle) over the same with 2; " + detail,
           at8 / at2);
}
CHM_BENCH_MEASUREMENT(rtpu_scaling, "rsem_handoff_8rtpus_over_2");

}  // namespace
}  // namespace chm::bench
