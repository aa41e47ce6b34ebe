// Peers: raw shared futex ping-pongs between two processes. The first wakes
// the other side every time, the cheapest way one Linux process can wake
// another; remote semaphore hand-off to a sleeping RTPU is judged against it.
// The second wakes a side only when it sleeps: the least any cross-process
// message that sleeps in receive can cost, the floor of msgq_wake_rt2.
#include <atomic>
#include <cstdint>

#include "../harness.hpp"
#include "../proc.hpp"

namespace chm::bench {
namespace {

// 1: the child's turn (a ping is out), 0: the parent's turn.
struct alignas(64) Turn {
    std::atomic<std::uint32_t> v{0};
};

void futex_pingpong(Session& s) {
    for_both_pinnings(s, "peer_futex_pingpong", "processes", [&](const std::string& row, const Pinning& p) {
        SharedObj<Turn> turn;
        std::atomic<std::uint32_t>* w = &turn->v;
        Child child(p.other, [w] {
            for (;;) {
                while (w->load(std::memory_order_acquire) == 0) futex_wait(w, 0);
                w->store(0, std::memory_order_release);
                futex_wake(w);
            }
            return 0;
        });
        s.time_ops(row, p.text + ", FUTEX_WAIT/FUTEX_WAKE (shared), SCHED_OTHER; RT/2",
                   [&](std::uint64_t n) {
                       for (std::uint64_t i = 0; i < n; ++i) {
                           w->store(1, std::memory_order_release);
                           futex_wake(w);
                           while (w->load(std::memory_order_acquire) == 1)
                               if (futex_wait(w, 1) != 0 && errno != EAGAIN)
                                   eintr_or_fail("futex_wait");
                       }
                   },
                   2);
    });
}
CHM_BENCH_MEASUREMENT(futex_pingpong, "peer_futex_pingpong_same_core", "peer_futex_pingpong_xcore");

// One direction of the hand-off: the sequence number last posted, and
// whether its reader sleeps on it.
struct alignas(64) Channel {
    std::atomic<std::uint32_t> seq{0};
    std::atomic<std::uint32_t> sleeping{0};

    // Both sides order a store before a load (Dekker): seq_cst throughout,
    // so a poster that reads sleeping == 0 is sure the reader sees seq.
    void post(std::uint32_t v) {
        seq.store(v);
        if (sleeping.load()) futex_wake(&seq);
    }
    void await(std::uint32_t v) {
        for (std::uint32_t cur; (cur = seq.load()) != v;) {
            sleeping.store(1);
            if ((cur = seq.load()) != v && futex_wait(&seq, cur) != 0 && errno != EAGAIN)
                eintr_or_fail("futex_wait");
            sleeping.store(0);
        }
    }
};
struct Channels {
    Channel down, up;
};

// Per round trip one FUTEX_WAKE (the parent's, which the child preempts),
// one FUTEX_WAIT (the child's, back to sleep) and two switches: what any
// design whose receiver sleeps in the kernel pays on one core.
void futex_handoff(Session& s) {
    const int cpu = s.cpu(0);
    Session::pin(cpu);
    SharedObj<Channels> ch;
    Channels* c = &*ch;
    Child child(cpu, [c] {
        for (std::uint32_t v = 1;; ++v) {
            c->down.await(v);
            c->up.post(v);
        }
        return 0;
    });
    std::uint32_t v = 0;  // carried across the timed runs, as the child's is
    s.time_ops("peer_futex_handoff_rt2_same_core",
               "two processes, both pinned " + s.cpu_name(0) +
                   ", a shared futex each way, FUTEX_WAKE only to a side that sleeps, SCHED_OTHER; RT/2",
               [&](std::uint64_t n) {
                   for (std::uint64_t i = 0; i < n; ++i) {
                       c->down.post(++v);
                       c->up.await(v);
                   }
               },
               2);
}
CHM_BENCH_MEASUREMENT(futex_handoff, "peer_futex_handoff_rt2_same_core");

}  // namespace
}  // namespace chm::bench
