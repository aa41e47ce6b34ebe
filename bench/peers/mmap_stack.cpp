// Peer: a fresh 64 KiB stack from the kernel, what a task spawn would cost
// if it mapped a stack each time (the reason Chimera pools and pre-faults).
#include <sys/mman.h>

#include <cstdint>

#include "../harness.hpp"

namespace chm::bench {
namespace {

constexpr std::size_t kStack = 64 * 1024;

void mmap_stack(Session& s) {
    Session::pin(s.cpu(0));
    for (const bool touch : {false, true}) {
        s.time_ops(touch ? "peer_mmap_stack_64k_touched" : "peer_mmap_stack_64k_untouched",
                   "pinned " + s.cpu_name(0) + ", MAP_PRIVATE|MAP_ANONYMOUS|MAP_STACK" +
                       (touch ? ", one write to the top page" : ""),
                   [&](std::uint64_t n) {
                       for (std::uint64_t i = 0; i < n; ++i) {
                           void* p = mmap(nullptr, kStack, PROT_READ | PROT_WRITE,
                                          MAP_PRIVATE | MAP_ANONYMOUS | MAP_STACK, -1, 0);
                           check(p != MAP_FAILED, "mmap");
                           // Stacks grow down: the first page used is the top one.
                           if (touch) static_cast<volatile char*>(p)[kStack - 64] = 1;
                           munmap(p, kStack);
                       }
                   });
    }
}
CHM_BENCH_MEASUREMENT(mmap_stack, "peer_mmap_stack_64k_untouched", "peer_mmap_stack_64k_touched");

}  // namespace
}  // namespace chm::bench
