// Randomised stress of the TLSF allocator: millions of allocate / aligned
// allocate / reallocate / free operations from a fixed seed (the same
// sequence on every target), block contents checked against patterns tied
// to each allocation, check() every kCheckEvery operations. The pool is
// sized so the random workload regularly runs it dry: failures are part of
// the test, and must leave the heap consistent.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "kernel/mem/tlsf.hpp"
#include "mem_test_util.hpp"

namespace chm::mem {
namespace {

using test::Rng;

std::size_t random_size(Rng& rng) {
    const unsigned r = static_cast<unsigned>(rng.next() % 1000);
    if (r < 600)
        return rng.range(1, 128);
    if (r < 900)
        return rng.range(129, 2048);
    if (r < 995)
        return rng.range(2049, 32768);
    return rng.range(32769, 524288);
}

std::size_t op_count() {
    // A knob for slow emulated runs; the default is the real test.
    if (const char* s = std::getenv("CHIMERA_MEM_STRESS_OPS"))
        return static_cast<std::size_t>(std::strtoul(s, nullptr, 10));
    return 2'000'000;
}

struct Slot {
    void* p = nullptr;
    std::size_t n = 0;
    std::uint32_t tag = 0;
};

TEST(TlsfStress, MillionsOfRandomOperations) {
    constexpr std::size_t kPool = std::size_t{16} << 20;
    constexpr std::size_t kSlots = 4096;
    constexpr std::size_t kCheckEvery = 10'000;
    test::Arena arena(kPool);
    ASSERT_NE(arena.data(), nullptr);
    Tlsf t;
    ASSERT_TRUE(t.add_pool(arena.data(), arena.size()));

    std::vector<Slot> slots(kSlots);
    Rng rng(0xC41DE7A5u);
    std::uint32_t next_tag = 1;
    std::size_t live = 0, allocs = 0, frees = 0, reallocs = 0, failures = 0, moved = 0;
    const std::size_t ops = op_count();

    for (std::size_t op = 1; op <= ops; ++op) {
        Slot& s = slots[rng.range(0, kSlots - 1)];
        if (!s.p) {
            const std::size_t n = random_size(rng);
            const bool aligned = rng.chance(5);
            const std::size_t align = std::size_t{1} << rng.range(4, 12);
            void* p = aligned ? t.allocate_aligned(align, n) : t.allocate(n);
            if (!p) {
                ++failures;
                continue;
            }
            ASSERT_EQ(reinterpret_cast<std::uintptr_t>(p) % (aligned ? align : Tlsf::kAlign), 0u);
            ASSERT_GE(Tlsf::usable_size(p), n);
            s = {p, n, next_tag++};
            test::fill(s.p, s.n, s.tag);
            ++allocs;
            ++live;
        } else if (rng.chance(60)) {
            ASSERT_TRUE(test::verify(s.p, s.n, s.n, s.tag)) << "op " << op;
            ASSERT_TRUE(t.free(s.p));
            s = {};
            ++frees;
            --live;
        } else {
            const std::size_t n = random_size(rng);
            void* q = t.reallocate(s.p, n);
            if (!q) {
                ++failures;
                ASSERT_TRUE(t.is_allocated(s.p));  // untouched
                ASSERT_TRUE(test::verify(s.p, s.n, s.n, s.tag));
                continue;
            }
            ASSERT_GE(Tlsf::usable_size(q), n);
            ASSERT_TRUE(test::verify(q, std::min(n, s.n), s.n, s.tag)) << "op " << op;
            moved += q != s.p;
            s = {q, n, next_tag++};
            test::fill(s.p, s.n, s.tag);
            ++reallocs;
        }
        if (op % kCheckEvery == 0) {
            CheckReport r;
            ASSERT_TRUE(t.check(&r)) << "op " << op << ": " << r.what << " at " << r.where;
            ASSERT_EQ(t.stats().used_blocks, live);
        }
    }
    std::printf("%zu ops: %zu allocs, %zu frees, %zu reallocs (%zu moved), %zu failures\n", ops,
                allocs, frees, reallocs, moved, failures);
    if (ops >= 100'000) {
        // The workload must have exercised every path, exhaustion included.
        EXPECT_GT(failures, 0u);
        EXPECT_GT(moved, 0u);
        EXPECT_GT(reallocs - moved, 0u);
    }
    for (Slot& s : slots) {
        if (!s.p)
            continue;
        ASSERT_TRUE(test::verify(s.p, s.n, s.n, s.tag));
        ASSERT_TRUE(t.free(s.p));
    }
    CheckReport r;
    EXPECT_TRUE(t.check(&r)) << r.what;
    const TlsfStats st = t.stats();
    EXPECT_EQ(st.used_blocks, 0u);
    EXPECT_EQ(st.free_blocks, 1u);  // everything merged back
    EXPECT_EQ(st.invalid_frees, 0u);
}

}  // namespace
}  // namespace chm::mem
