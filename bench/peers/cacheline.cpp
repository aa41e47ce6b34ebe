// Peer: the cross-core cache-line ping-pong, two threads spinning on one
// shared line. No wake-up can beat it; a remote semaphore hand-off to a
// polling RTPU is judged against the same loops run by its own two tasks
// (peer_cacheline_pingpong_rtpus, ipc/rsem_wake_rows.cpp).
#include <cstdint>

#include "../harness.hpp"
#include "../proc.hpp"
#include "cacheline.hpp"

namespace chm::bench {
namespace {

void cacheline_pingpong(Session& s) {
    s.need_cpus(2);
    Session::pin(s.cpu(0));
    PingLine line;
    Partner partner(s.cpu(1), [&] { answer_pings(line); },
                    [&] { line.seq.store(kPingStop, std::memory_order_release); });
    s.time_custom("peer_cacheline_pingpong_xcore",
                  "two spinning threads pinned " + s.cpu_name(0) + " and " + s.cpu_name(1) +
                      "; one hand-off (RT/2)",
                  [&](std::uint64_t n) { return send_pings(line, n); }, 2);
}
CHM_BENCH_MEASUREMENT(cacheline_pingpong, "peer_cacheline_pingpong_xcore");

}  // namespace
}  // namespace chm::bench
