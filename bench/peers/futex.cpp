// Peer: a raw shared futex ping-pong between two processes, the cheapest way
// one Linux process can wake another; remote semaphore hand-off to a
// sleeping RTPU is judged against it.
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

}  // namespace
}  // namespace chm::bench
