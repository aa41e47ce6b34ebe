// Unit tests of the TLSF allocator on pools of our own: size classes,
// split and merge, alignment, realloc in place, exhaustion, pool growth,
// and check() finding deliberately corrupted state.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstring>
#include <vector>

#include "kernel/mem/tlsf.hpp"
#include "mem_test_util.hpp"

namespace chm::mem {
namespace {

using test::Arena;
constexpr std::size_t kA = Tlsf::kAlign;
constexpr std::size_t kH = Tlsf::kHeader;

::testing::AssertionResult consistent(const Tlsf& t) {
    CheckReport r;
    if (t.check(&r))
        return ::testing::AssertionSuccess();
    return ::testing::AssertionFailure() << "check(): " << r.what << " at " << r.where;
}

// A fresh allocator over a fresh arena.
struct Fixture : ::testing::Test {
    static constexpr std::size_t kPool = std::size_t{1} << 20;
    Arena arena{kPool};
    Tlsf tlsf;
    void SetUp() override {
        ASSERT_NE(arena.data(), nullptr);
        ASSERT_TRUE(tlsf.add_pool(arena.data(), arena.size()));
    }
    void TearDown() override { EXPECT_TRUE(consistent(tlsf)); }
};

using TlsfTest = Fixture;

TEST(TlsfGeometry, SizeClassesAreOrderedAndExactWhenSmall) {
    Tlsf::Index prev{0, 0};
    for (std::size_t s = Tlsf::kMinBlock; s < (std::size_t{1} << 24); s += s / 64 + kA) {
        const Tlsf::Index i = Tlsf::mapping(s);
        ASSERT_LT(i.fl, Tlsf::kFlCount);
        ASSERT_LT(i.sl, Tlsf::kSlCount);
        ASSERT_TRUE(i.fl > prev.fl || (i.fl == prev.fl && i.sl >= prev.sl)) << s;
        prev = i;
    }
    // Below kSmallBlock every kAlign step has a list of its own.
    for (std::size_t s = Tlsf::kMinBlock; s + kA < Tlsf::kSmallBlock; s += kA)
        EXPECT_NE(Tlsf::mapping(s).sl, Tlsf::mapping(s + kA).sl);
    EXPECT_EQ(Tlsf::mapping(Tlsf::kMaxPool).fl, Tlsf::kFlCount - 1);
}

TEST_F(TlsfTest, FreshPoolIsOneFreeBlock) {
    const TlsfStats s = tlsf.stats();
    EXPECT_EQ(s.pool_bytes, kPool);
    EXPECT_EQ(s.pools, 1u);
    EXPECT_EQ(s.free_blocks, 1u);
    EXPECT_EQ(s.used_blocks, 0u);
    EXPECT_EQ(s.free_bytes, kPool - Tlsf::kPoolOverhead - kH);
    EXPECT_EQ(s.largest_free, s.free_bytes);
    EXPECT_EQ(s.used_bytes + s.free_bytes + s.overhead_bytes, s.pool_bytes);
}

TEST_F(TlsfTest, EveryBlockIsAlignedAndLargeEnough) {
    std::vector<void*> ps;
    for (std::size_t n = 0; n <= 2100; n += 7) {
        void* p = tlsf.allocate(n);
        ASSERT_NE(p, nullptr) << n;
        EXPECT_EQ(reinterpret_cast<std::uintptr_t>(p) % kA, 0u);
        EXPECT_GE(Tlsf::usable_size(p), n);
        EXPECT_TRUE(tlsf.is_allocated(p));
        std::memset(p, 0xab, n);
        ps.push_back(p);
    }
    EXPECT_TRUE(consistent(tlsf));
    EXPECT_EQ(tlsf.stats().used_blocks, ps.size());
    for (void* p : ps)
        EXPECT_TRUE(tlsf.free(p));
    EXPECT_EQ(tlsf.stats().free_blocks, 1u);
}

TEST_F(TlsfTest, SplitAndMergeWithBothNeighbours) {
    // A fresh pool hands blocks out back to back.
    void* a = tlsf.allocate(100);
    void* b = tlsf.allocate(200);
    void* c = tlsf.allocate(300);
    ASSERT_TRUE(a && b && c);
    auto* ca = static_cast<char*>(a);
    EXPECT_EQ(static_cast<char*>(b), ca + Tlsf::usable_size(a) + kH);
    EXPECT_EQ(static_cast<char*>(c), static_cast<char*>(b) + Tlsf::usable_size(b) + kH);
    EXPECT_EQ(tlsf.stats().free_blocks, 1u);  // the tail

    EXPECT_TRUE(tlsf.free(b));  // a hole between two used blocks
    EXPECT_EQ(tlsf.stats().free_blocks, 2u);
    EXPECT_TRUE(consistent(tlsf));
    EXPECT_TRUE(tlsf.free(a));  // merges forward into b's hole
    EXPECT_EQ(tlsf.stats().free_blocks, 2u);
    EXPECT_TRUE(consistent(tlsf));
    // The merged hole is reused for a request that needs both.
    void* ab = tlsf.allocate(100 + 200);
    EXPECT_EQ(ab, a);
    EXPECT_TRUE(tlsf.free(ab));
    EXPECT_TRUE(tlsf.free(c));  // merges backward and forward: one block
    const TlsfStats s = tlsf.stats();
    EXPECT_EQ(s.free_blocks, 1u);
    EXPECT_EQ(s.free_bytes, kPool - Tlsf::kPoolOverhead - kH);
}

TEST_F(TlsfTest, AlignedAllocation) {
    std::vector<void*> ps;
    for (std::size_t align = 1; align <= 65536; align <<= 1) {
        for (std::size_t n : {0, 1, 24, 100, 1000, 5000}) {
            void* p = tlsf.allocate_aligned(align, n);
            ASSERT_NE(p, nullptr) << align << " " << n;
            EXPECT_EQ(reinterpret_cast<std::uintptr_t>(p) % align, 0u);
            EXPECT_EQ(reinterpret_cast<std::uintptr_t>(p) % kA, 0u);
            EXPECT_GE(Tlsf::usable_size(p), n);
            std::memset(p, 0x5c, n);
            ps.push_back(p);
            // A small ordinary block between aligned ones exercises the
            // gaps left in front of them.
            ps.push_back(tlsf.allocate(8));
        }
    }
    EXPECT_TRUE(consistent(tlsf));
    for (void* p : ps)
        EXPECT_TRUE(tlsf.free(p));
    EXPECT_EQ(tlsf.stats().free_blocks, 1u);
    EXPECT_EQ(tlsf.allocate_aligned(3, 10), nullptr);
    EXPECT_EQ(tlsf.allocate_aligned(0, 10), nullptr);
    EXPECT_EQ(tlsf.allocate_aligned(48, 10), nullptr);
}

TEST_F(TlsfTest, ReallocShrinksInPlaceAndKeepsContents) {
    auto* p = static_cast<unsigned char*>(tlsf.allocate(4000));
    ASSERT_NE(p, nullptr);
    void* guard = tlsf.allocate(16);  // keeps the tail from being the neighbour
    for (int i = 0; i < 4000; ++i)
        p[i] = static_cast<unsigned char>(i * 13);
    const std::size_t free_before = tlsf.stats().free_blocks;
    void* q = tlsf.reallocate(p, 100);
    EXPECT_EQ(q, p);
    EXPECT_GE(Tlsf::usable_size(q), 100u);
    EXPECT_LT(Tlsf::usable_size(q), 4000u);
    EXPECT_EQ(tlsf.stats().free_blocks, free_before + 1);  // the cut-off tail
    for (int i = 0; i < 100; ++i)
        ASSERT_EQ(p[i], static_cast<unsigned char>(i * 13));
    EXPECT_TRUE(consistent(tlsf));
    EXPECT_TRUE(tlsf.free(q));
    EXPECT_TRUE(tlsf.free(guard));
}

TEST_F(TlsfTest, ReallocGrowsInPlaceIntoAFreeSuccessor) {
    auto* a = static_cast<unsigned char*>(tlsf.allocate(100));
    void* b = tlsf.allocate(400);
    void* c = tlsf.allocate(16);
    for (int i = 0; i < 100; ++i)
        a[i] = static_cast<unsigned char>(i + 1);
    ASSERT_TRUE(tlsf.free(b));
    void* q = tlsf.reallocate(a, 300);
    EXPECT_EQ(q, a);
    EXPECT_GE(Tlsf::usable_size(q), 300u);
    for (int i = 0; i < 100; ++i)
        ASSERT_EQ(a[i], i + 1);
    EXPECT_TRUE(consistent(tlsf));
    // No room left beside it (c is in use): the block moves, contents follow.
    void* moved = tlsf.reallocate(q, 2000);
    ASSERT_NE(moved, nullptr);
    EXPECT_NE(moved, q);
    for (int i = 0; i < 100; ++i)
        ASSERT_EQ(static_cast<unsigned char*>(moved)[i], i + 1);
    EXPECT_TRUE(consistent(tlsf));
    EXPECT_TRUE(tlsf.free(moved));
    EXPECT_TRUE(tlsf.free(c));
    EXPECT_EQ(tlsf.stats().free_blocks, 1u);
}

TEST_F(TlsfTest, ReallocEdgeCases) {
    void* p = tlsf.reallocate(nullptr, 50);  // acts as allocate
    ASSERT_NE(p, nullptr);
    EXPECT_EQ(tlsf.reallocate(p, 0), nullptr);  // acts as free
    EXPECT_EQ(tlsf.stats().used_blocks, 0u);
    void* q = tlsf.allocate(50);
    EXPECT_EQ(tlsf.reallocate(q, Tlsf::kMaxRequest + 1), nullptr);
    EXPECT_TRUE(tlsf.is_allocated(q));  // untouched on failure
    EXPECT_EQ(tlsf.reallocate(q, kPool), nullptr);
    EXPECT_TRUE(tlsf.is_allocated(q));
    EXPECT_TRUE(tlsf.free(q));
}

TEST_F(TlsfTest, ExhaustionReturnsNullAndStaysConsistent) {
    std::vector<void*> ps;
    for (;;) {
        void* p = tlsf.allocate(1000);
        if (!p)
            break;
        ps.push_back(p);
    }
    EXPECT_GT(ps.size(), kPool / (1000 + kH + kA) - 2);
    EXPECT_TRUE(consistent(tlsf));
    const TlsfStats full = tlsf.stats();
    EXPECT_LT(full.largest_free, 1000u + kH + kA);
    EXPECT_EQ(tlsf.allocate(1000), nullptr);
    EXPECT_EQ(tlsf.allocate(kPool), nullptr);
    EXPECT_EQ(tlsf.allocate(Tlsf::kMaxRequest + 1), nullptr);
    EXPECT_EQ(tlsf.allocate_aligned(4096, 1000), nullptr);
    EXPECT_EQ(tlsf.stats().used_blocks, full.used_blocks);
    EXPECT_TRUE(consistent(tlsf));
    // Small requests still fit in what is left, if anything is.
    for (void* p : ps)
        ASSERT_TRUE(tlsf.free(p));
    EXPECT_EQ(tlsf.stats().free_blocks, 1u);
    EXPECT_NE(tlsf.allocate(kPool / 2), nullptr);
}

TEST_F(TlsfTest, DoubleFreeAndWildPointersAreRefused) {
    void* a = tlsf.allocate(64);
    void* b = tlsf.allocate(64);
    ASSERT_TRUE(tlsf.free(a));
    EXPECT_FALSE(tlsf.free(a));  // double free: its header says free
    EXPECT_FALSE(tlsf.free(static_cast<char*>(b) + 1));  // misaligned
    EXPECT_FALSE(tlsf.free(static_cast<char*>(b) + 2 * kA));  // mid-block
    EXPECT_EQ(tlsf.stats().invalid_frees, 3u);
    EXPECT_TRUE(consistent(tlsf));
    EXPECT_TRUE(tlsf.free(b));
}

TEST_F(TlsfTest, CheckFindsACorruptedSizeWord) {
    void* a = tlsf.allocate(64);
    void* b = tlsf.allocate(64);
    void* c = tlsf.allocate(64);
    auto* size_word = static_cast<std::size_t*>(b) - 1;  // [prev_size][size|flags]
    const std::size_t saved = *size_word;
    *size_word = saved + 4 * kA;  // claims to swallow part of c
    CheckReport r;
    EXPECT_FALSE(tlsf.check(&r));
    ASSERT_NE(r.what, nullptr);
    EXPECT_NE(r.where, nullptr);
    std::printf("detected: %s\n", r.what);
    *size_word = saved ^ 1;  // flag flipped: "free" but on no list
    EXPECT_FALSE(tlsf.check(&r));
    std::printf("detected: %s\n", r.what);
    *size_word = 3;  // garbage
    EXPECT_FALSE(tlsf.check(&r));
    std::printf("detected: %s\n", r.what);
    EXPECT_FALSE(tlsf.free(b));  // free() refuses the damaged header too
    *size_word = saved;
    EXPECT_TRUE(consistent(tlsf));
    for (void* p : {a, b, c})
        EXPECT_TRUE(tlsf.free(p));
}

TEST_F(TlsfTest, CheckFindsAnOverrunIntoTheNextHeader) {
    void* a = tlsf.allocate(40);
    void* b = tlsf.allocate(40);
    // Writing past a's usable size lands on b's boundary tag.
    auto* tag = static_cast<std::size_t*>(b) - 2;
    const std::size_t saved = *tag;
    std::memset(a, 0x41, Tlsf::usable_size(a) + sizeof(std::size_t));
    CheckReport r;
    EXPECT_FALSE(tlsf.check(&r));
    std::printf("detected: %s\n", r.what);
    *tag = saved;
    EXPECT_TRUE(consistent(tlsf));
    EXPECT_TRUE(tlsf.free(a));
    EXPECT_TRUE(tlsf.free(b));
}

TEST_F(TlsfTest, CheckFindsBrokenFreeListLinks) {
    void* a = tlsf.allocate(64);
    void* b = tlsf.allocate(64);
    void* c = tlsf.allocate(64);
    ASSERT_TRUE(tlsf.free(b));
    auto** link_next = static_cast<void**>(b);  // a free block's payload holds its links
    void* saved = *link_next;
    *link_next = static_cast<char*>(c) - kH;  // an allocated block smuggled in
    CheckReport r;
    EXPECT_FALSE(tlsf.check(&r));
    std::printf("detected: %s\n", r.what);
    *link_next = static_cast<char*>(b) - kH;  // a cycle
    EXPECT_FALSE(tlsf.check(&r));
    std::printf("detected: %s\n", r.what);
    *link_next = reinterpret_cast<void*>(0x10);  // outside every pool
    EXPECT_FALSE(tlsf.check(&r));
    std::printf("detected: %s\n", r.what);
    *link_next = saved;
    EXPECT_TRUE(consistent(tlsf));
    EXPECT_TRUE(tlsf.free(a));
    EXPECT_TRUE(tlsf.free(c));
}

TEST(TlsfPools, AdjacentRangesGrowOnePool) {
    Arena arena(std::size_t{1} << 20);
    Tlsf t;
    const std::size_t half = arena.size() / 2;
    ASSERT_TRUE(t.add_pool(arena.data(), half));
    void* small = t.allocate(100);  // the old pool's tail stays free
    EXPECT_EQ(t.allocate(half), nullptr);
    ASSERT_TRUE(t.add_pool(arena.data() + half, half));
    TlsfStats s = t.stats();
    EXPECT_EQ(s.pools, 1u);
    EXPECT_EQ(s.free_blocks, 1u);  // old tail and new range merged
    EXPECT_EQ(s.pool_bytes, arena.size());
    void* big = t.allocate(half + half / 2);  // spans the seam
    EXPECT_NE(big, nullptr);
    EXPECT_TRUE(consistent(t));
    EXPECT_TRUE(t.free(big));
    EXPECT_TRUE(t.free(small));
    EXPECT_TRUE(consistent(t));
    EXPECT_EQ(t.stats().free_blocks, 1u);
}

TEST(TlsfPools, SeparatePoolsOverlapAndTinyRanges) {
    Arena arena(std::size_t{1} << 20);
    Tlsf t;
    unsigned char* m = arena.data();
    ASSERT_TRUE(t.add_pool(m + 1, 4096 - 1));  // unaligned start is trimmed
    ASSERT_TRUE(t.add_pool(m + 65536, 65536));  // not adjacent: second pool
    EXPECT_FALSE(t.add_pool(m + 65536 + 4096, 4096));  // overlaps
    EXPECT_FALSE(t.add_pool(m + 300000, Tlsf::kMinPool / 2));  // too small
    EXPECT_TRUE(t.add_pool(m + 400000, Tlsf::kMinPool));  // just enough
    EXPECT_EQ(t.stats().pools, 3u);
    EXPECT_TRUE(consistent(t));
    // Requests land in whichever pool has room; all are freed consistently.
    std::vector<void*> ps;
    while (void* p = t.allocate(500))
        ps.push_back(p);
    EXPECT_GT(ps.size(), 65536u / 600);
    EXPECT_TRUE(t.contains(ps.front()));
    EXPECT_FALSE(t.contains(m + 200000));
    EXPECT_TRUE(consistent(t));
    for (void* p : ps)
        EXPECT_TRUE(t.free(p));
    EXPECT_EQ(t.stats().free_blocks, 3u);
    EXPECT_TRUE(consistent(t));
    void* tiny = t.allocate(Tlsf::kMinBlock - kH);
    EXPECT_NE(tiny, nullptr);
    EXPECT_TRUE(t.free(tiny));
}

TEST(TlsfPools, EmptyAllocatorRefusesEverything) {
    Tlsf t;
    EXPECT_EQ(t.allocate(1), nullptr);
    EXPECT_EQ(t.allocate_aligned(64, 1), nullptr);
    EXPECT_TRUE(t.free(nullptr));
    EXPECT_TRUE(consistent(t));
    EXPECT_EQ(t.stats().largest_free, 0u);
}

}  // namespace
}  // namespace chm::mem
