// Peer: reading and writing a 64 KiB local array, per 8-byte word; the
// baseline of the shared-memory access overhead rows (see memory.hpp).
#include "memory.hpp"

#include <vector>

#include "../harness.hpp"

namespace chm::bench {

std::uint64_t sum_words(const std::uint64_t* p, std::size_t n) {
    std::uint64_t s = 0;
    for (std::size_t i = 0; i < n; ++i) s += p[i];
    return s;
}

void fill_words(std::uint64_t* p, std::size_t n, std::uint64_t v) {
    for (std::size_t i = 0; i < n; ++i) p[i] = v + i;
}

namespace {

constexpr std::size_t kWords = 64 * 1024 / 8;

void array_access(Session& s) {
    Session::pin(s.cpu(0));
    std::vector<std::uint64_t> a(kWords, 1);
    const std::string where = "pinned " + s.cpu_name(0) + ", 64 KiB (cache-resident), per 8-byte word";
    volatile std::uint64_t sink = 0;
    s.time_ops("peer_array_read", where,
               [&](std::uint64_t n) {
                   for (std::uint64_t i = 0; i < n; ++i) sink = sink + sum_words(a.data(), kWords);
               },
               double(kWords));
    s.time_ops("peer_array_write", where,
               [&](std::uint64_t n) {
                   for (std::uint64_t i = 0; i < n; ++i) fill_words(a.data(), kWords, i);
               },
               double(kWords));
}
CHM_BENCH_MEASUREMENT(array_access, "peer_array_read", "peer_array_write");

}  // namespace
}  // namespace chm::bench
