// Peer: the cross-core cache-line ping-pong, two threads spinning on one
// shared line. No wake-up can beat it; a remote semaphore hand-off to a
// polling RTPU is judged against it.
#include <atomic>
#include <cstdint>

#include "../harness.hpp"
#include "../proc.hpp"

namespace chm::bench {
namespace {

inline void cpu_relax() {
#if defined(__x86_64__)
    __builtin_ia32_pause();
#elif defined(__aarch64__)
    __asm__ __volatile__("yield");
#endif
}

void cacheline_pingpong(Session& s) {
    s.need_cpus(2);
    Session::pin(s.cpu(0));
    // The line that moves, and (on its own line) the flag that ends it.
    struct alignas(64) Line {
        std::atomic<std::uint64_t> seq{0};
    };
    struct alignas(64) Flag {
        std::atomic<bool> stop{false};
    };
    Line line;
    Flag flag;
    Partner partner(
        s.cpu(1),
        [&] {
            // Answer every odd value with the next even one.
            std::uint64_t want = 1;
            for (;;) {
                while (line.seq.load(std::memory_order_acquire) != want) {
                    if (flag.stop.load(std::memory_order_relaxed)) return;
                    cpu_relax();
                }
                line.seq.store(want + 1, std::memory_order_release);
                want += 2;
            }
        },
        [&] { flag.stop = true; });
    std::uint64_t v = 0;
    s.time_ops("peer_cacheline_pingpong_xcore",
               "two spinning threads pinned " + s.cpu_name(0) + " and " + s.cpu_name(1) +
                   "; one hand-off (RT/2)",
               [&](std::uint64_t n) {
                   for (std::uint64_t i = 0; i < n; ++i) {
                       line.seq.store(v + 1, std::memory_order_release);
                       std::uint32_t spins = 0;
                       while (line.seq.load(std::memory_order_acquire) != v + 2) {
                           cpu_relax();
                           if (++spins == 0 && abort_reason())
                               throw std::runtime_error(abort_reason());
                       }
                       v += 2;
                   }
               },
               2);
}
CHM_BENCH_MEASUREMENT(cacheline_pingpong, "peer_cacheline_pingpong_xcore");

}  // namespace
}  // namespace chm::bench
