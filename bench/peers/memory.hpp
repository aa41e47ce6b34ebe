// The access loops behind peer_array_read/write. The shared-memory overhead
// rows must run these same functions on an attached global segment: "zero
// software overhead" means the same code at the same speed.
#pragma once

#include <cstddef>
#include <cstdint>

namespace chm::bench {

// Out of line so the compiler cannot specialise them for one buffer.
[[gnu::noinline]] std::uint64_t sum_words(const std::uint64_t* p, std::size_t n);
[[gnu::noinline]] void fill_words(std::uint64_t* p, std::size_t n, std::uint64_t v);

}  // namespace chm::bench
