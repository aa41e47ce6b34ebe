// Evidence for the O(1) claim, by counting rather than timing: the
// allocator counts its bitmap and list steps per operation
// (Tlsf::last_op_steps), and this test drives every operation over pools
// from 256 KiB to 128 MiB, fresh and fragmented (thousands of holes across
// all size classes, and ten thousand holes in a single class), asserting
// that no operation ever exceeds a constant bound derived from the code and
// that the canonical worst cases cost exactly the same in every heap.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <vector>

#include "kernel/mem/tlsf.hpp"
#include "mem_test_util.hpp"

namespace chm::mem {
namespace {

// Per-operation bounds read off tlsf.cpp: a search is at most two bitmap
// lookups; a list insert or remove is one step; a split or a merge is one
// step plus the list operations it causes.
//   allocate:          search 2 + remove 1 + split 1 + insert 1 (+ merge 2, never
//                      taken: a free block's successor is in use)          <= 7
//   allocate_aligned:  allocate + front split 1 + its insert 1            <= 9
//   free:              merge back 2 + merge forward 2 + insert 1          <= 5
//   reallocate:        in place <= 5; moving = allocate + free           <= 12
constexpr unsigned kAllocBound = 7;
constexpr unsigned kAlignedBound = 9;
constexpr unsigned kFreeBound = 5;
constexpr unsigned kReallocBound = 12;

struct Maxima {
    unsigned alloc = 0, aligned = 0, free = 0, realloc = 0;
    unsigned free_between_holes = 0;  // the canonical double merge
};

void note(unsigned& max, unsigned steps) { max = std::max(max, steps); }

// Leave `count` isolated holes of random sizes: allocate hole/wall pairs
// back to back from the pool's tail, then free the holes (their neighbours
// are walls, so nothing merges).
std::vector<void*> make_holes(Tlsf& t, test::Rng& rng, std::size_t count, bool one_class) {
    std::vector<void*> holes, walls;
    for (std::size_t i = 0; i < count; ++i) {
        void* hole = t.allocate(one_class ? 100 : rng.range(1, 4096));
        void* wall = t.allocate(16);
        if (!hole || !wall) {
            t.free(hole);
            t.free(wall);
            break;
        }
        holes.push_back(hole);
        walls.push_back(wall);
    }
    for (void* h : holes)
        t.free(h);
    return walls;
}

Maxima measure(Tlsf& t, test::Rng& rng, std::size_t pool) {
    Maxima m;
    // Free a block whose neighbours are both free: merge back, merge
    // forward, insert. Blocks larger than any hole come from the tail, back
    // to back.
    {
        void* a = t.allocate(8192);
        void* b = t.allocate(8192);
        void* c = t.allocate(8192);
        void* wall = t.allocate(8192);
        EXPECT_EQ(static_cast<char*>(b), static_cast<char*>(a) + Tlsf::usable_size(a) + Tlsf::kHeader);
        EXPECT_EQ(static_cast<char*>(c), static_cast<char*>(b) + Tlsf::usable_size(b) + Tlsf::kHeader);
        t.free(a);
        t.free(c);
        t.free(b);
        m.free_between_holes = t.last_op_steps();
        t.free(wall);
    }
    const std::size_t sizes[] = {0, 1, 24, 100, 200, 500, 1000, 3000, 4096, 10000,
                                 65536, 300000, pool / 4};
    for (std::size_t n : sizes) {
        void* p = t.allocate(n);
        note(m.alloc, t.last_op_steps());
        if (!p)
            continue;
        void* q = t.reallocate(p, n / 2 + 1);  // shrink in place
        note(m.realloc, t.last_op_steps());
        void* r = t.reallocate(q, n * 2 + 64);  // grow: in place or moved
        note(m.realloc, t.last_op_steps());
        t.free(r ? r : q);
        note(m.free, t.last_op_steps());
        for (std::size_t align : {64u, 4096u}) {
            void* a = t.allocate_aligned(align, n);
            note(m.aligned, t.last_op_steps());
            t.free(a);
            note(m.free, t.last_op_steps());
        }
    }
    // A burst of random operations on top, as a real workload would do.
    std::vector<void*> live;
    for (int i = 0; i < 2000; ++i) {
        if (live.empty() || rng.chance(55)) {
            void* p = t.allocate(rng.range(1, 2000));
            note(m.alloc, t.last_op_steps());
            if (p)
                live.push_back(p);
        } else {
            const std::size_t k = rng.range(0, live.size() - 1);
            t.free(live[k]);
            note(m.free, t.last_op_steps());
            live[k] = live.back();
            live.pop_back();
        }
    }
    for (void* p : live)
        t.free(p);
    return m;
}

TEST(TlsfBounds, StepsPerOperationAreBoundedIndependentlyOfHeapSizeAndFragmentation) {
    struct Scenario {
        const char* name;
        std::size_t pool;
        std::size_t holes;
        bool one_class;
    };
    const Scenario scenarios[] = {
        {"256K fresh", std::size_t{256} << 10, 0, false},
        {"256K holes", std::size_t{256} << 10, 40, false},
        {"16M fresh", std::size_t{16} << 20, 0, false},
        {"16M holes", std::size_t{16} << 20, 5000, false},
        {"128M fresh", std::size_t{128} << 20, 0, false},
        {"128M holes", std::size_t{128} << 20, 10000, false},
        {"128M 10k holes in one list", std::size_t{128} << 20, 10000, true},
    };
    std::printf("%-28s %8s %6s %7s %5s %8s %12s\n", "heap", "free blks", "alloc", "aligned",
                "free", "realloc", "double merge");
    for (const Scenario& sc : scenarios) {
        test::Arena arena(sc.pool);
        ASSERT_NE(arena.data(), nullptr) << sc.name;
        Tlsf t;
        ASSERT_TRUE(t.add_pool(arena.data(), arena.size()));
        test::Rng rng(42);
        std::vector<void*> walls = make_holes(t, rng, sc.holes, sc.one_class);
        const std::size_t free_blocks = t.stats().free_blocks;
        const Maxima m = measure(t, rng, sc.pool);
        std::printf("%-28s %8zu %6u %7u %5u %8u %12u\n", sc.name, free_blocks, m.alloc, m.aligned,
                    m.free, m.realloc, m.free_between_holes);
        EXPECT_LE(m.alloc, kAllocBound) << sc.name;
        EXPECT_LE(m.aligned, kAlignedBound) << sc.name;
        EXPECT_LE(m.free, kFreeBound) << sc.name;
        EXPECT_LE(m.realloc, kReallocBound) << sc.name;
        EXPECT_EQ(m.free_between_holes, 5u) << sc.name;
        if (sc.holes >= 5000) {
            EXPECT_GE(free_blocks, sc.holes) << sc.name;
        }
        CheckReport r;
        EXPECT_TRUE(t.check(&r)) << sc.name << ": " << r.what;
        for (void* w : walls)
            t.free(w);
        EXPECT_EQ(t.stats().free_blocks, 1u) << sc.name;
    }
}

// The one place a list could be searched is the list a request maps to. It
// never is: with ten thousand holes of one size in one list, an allocation
// of that size takes the head, in the same number of steps as with one.
TEST(TlsfBounds, ALongListIsNeverWalked) {
    test::Arena arena(std::size_t{16} << 20);
    Tlsf t;
    ASSERT_TRUE(t.add_pool(arena.data(), arena.size()));
    test::Rng rng(7);
    std::vector<void*> walls = make_holes(t, rng, 1, true);
    void* p = t.allocate(100);
    const unsigned one = t.last_op_steps();
    t.free(p);
    std::vector<void*> more = make_holes(t, rng, 10000, true);
    ASSERT_GE(t.stats().free_blocks, 10000u);
    p = t.allocate(100);
    EXPECT_EQ(t.last_op_steps(), one);
    t.free(p);
    for (void* w : walls)
        t.free(w);
    for (void* w : more)
        t.free(w);
    EXPECT_TRUE(t.check());
}

}  // namespace
}  // namespace chm::mem
