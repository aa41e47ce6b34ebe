// Helpers shared by the allocator tests: page-backed arenas for pools, a
// portable fixed-seed generator (the same sequence on every target), and
// fill/verify patterns that tie a block's contents to its identity.
#pragma once

#include <sys/mman.h>

#include <cstddef>
#include <cstdint>

namespace chm::mem::test {

// Anonymous memory for a pool. MAP_NORESERVE: a big pool costs only the
// pages the allocator touches (headers), so size-independence tests can use
// pools far larger than they fill.
class Arena {
public:
    explicit Arena(std::size_t bytes) : bytes_(bytes) {
        void* p = mmap(nullptr, bytes, PROT_READ | PROT_WRITE,
                       MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
        mem_ = p == MAP_FAILED ? nullptr : static_cast<unsigned char*>(p);
    }
    ~Arena() {
        if (mem_)
            munmap(mem_, bytes_);
    }
    Arena(const Arena&) = delete;
    Arena& operator=(const Arena&) = delete;

    unsigned char* data() const { return mem_; }
    std::size_t size() const { return bytes_; }

private:
    unsigned char* mem_ = nullptr;
    std::size_t bytes_;
};

// splitmix64: plain uint64_t arithmetic, so the same seed gives the same
// sequence on x86-64 and m68k (std:: distributions promise no such thing).
class Rng {
public:
    explicit Rng(std::uint64_t seed) : s_(seed) {}
    std::uint64_t next() {
        std::uint64_t z = (s_ += 0x9e3779b97f4a7c15ull);
        z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
        z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
        return z ^ (z >> 31);
    }
    // Uniform-enough in [lo, hi] for test purposes.
    std::size_t range(std::size_t lo, std::size_t hi) {
        return lo + static_cast<std::size_t>(next() % (hi - lo + 1));
    }
    bool chance(unsigned percent) { return next() % 100 < percent; }

private:
    std::uint64_t s_;
};

// Write a pattern derived from `tag` into every 8th byte and the last byte
// (cheap enough for millions of operations, dense enough that any overlap
// of two blocks, which is at least one minimal block long, is caught).
inline void fill(void* p, std::size_t n, std::uint32_t tag) {
    auto* b = static_cast<unsigned char*>(p);
    for (std::size_t i = 0; i < n; i += 8)
        b[i] = static_cast<unsigned char>(tag + i * 7);
    if (n)
        b[n - 1] = static_cast<unsigned char>(tag ^ 0x5a);
}

// Check the first `n` bytes of a block filled with fill(p, filled, tag).
inline bool verify(const void* p, std::size_t n, std::size_t filled, std::uint32_t tag) {
    const auto* b = static_cast<const unsigned char*>(p);
    for (std::size_t i = 0; i < n && i < filled; i += 8)
        if (b[i] != static_cast<unsigned char>(tag + i * 7) && i != filled - 1)
            return false;
    if (n >= filled && filled && b[filled - 1] != static_cast<unsigned char>(tag ^ 0x5a))
        return false;
    return true;
}

}  // namespace chm::mem::test
