// The process heap and the public C API (chm_malloc family): chunked commit
// from the reservation, exhaustion, errno conventions, corruption reported
// by chm_mem_check, the preemption hooks, fork, and four threads hammering
// one heap. libchimera interposes on malloc, so this program (gtest and the
// C++ library included) runs on the very heap under test, which it
// reserved before main; meson runs it with CHIMERA_HEAP_MB=64.
#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <thread>
#include <vector>

#include "chimera/kernel.h"
#include "chimera/mem.h"
#include "kernel/mem/heap.hpp"
#include "mem_test_util.hpp"

namespace chm::mem {
namespace {

struct chm_mem_stats stats() {
    struct chm_mem_stats s{};
    EXPECT_EQ(chm_mem_stats(&s), 0);
    return s;
}

// The reservation the heap should have made, from the environment.
std::size_t expected_reservation() {
    const char* s = std::getenv("CHIMERA_HEAP_MB");
    const std::size_t mb = s && std::atoi(s) > 0 ? static_cast<std::size_t>(std::atoi(s))
                                                 : kHeapDefaultMb;
    return mb << 20;
}

// Tests that fill the whole reservation only run on a small one.
constexpr std::size_t kSmallReservation = std::size_t{256} << 20;

TEST(Heap, CommitsTheReservationInChunks) {
    void* p = chm_malloc(100);
    ASSERT_NE(p, nullptr);
    EXPECT_TRUE(heap_owns(p));
    const struct chm_mem_stats s = stats();
    EXPECT_EQ(s.reserved_bytes, expected_reservation());
    EXPECT_EQ(s.committed_bytes % kHeapChunk, 0u);
    EXPECT_GE(s.committed_bytes, kHeapChunk);
    EXPECT_GE(s.used_bytes, 100u);
    EXPECT_EQ(s.used_bytes + s.free_bytes + s.overhead_bytes, s.committed_bytes);
    // More than is committed: the heap commits another chunk (or more).
    const std::size_t big = s.committed_bytes + kHeapChunk / 2;
    void* q = chm_malloc(big);
    ASSERT_NE(q, nullptr);
    std::memset(q, 1, big);  // committed memory really is writable
    const struct chm_mem_stats t = stats();
    EXPECT_GT(t.committed_bytes, s.committed_bytes);
    EXPECT_GT(t.commits, s.commits);
    EXPECT_EQ(t.committed_bytes % kHeapChunk, 0u);
    EXPECT_EQ(heap_stats().tlsf.pools, 1u);  // chunks grow the one pool
    chm_free(q);
    chm_free(p);
    EXPECT_EQ(chm_mem_check(), 0);
    // Once committed, memory stays: the same request needs no new commit.
    void* again = chm_malloc(big);
    EXPECT_EQ(stats().commits, t.commits);
    chm_free(again);
}

TEST(Heap, ExhaustingTheReservationFailsCleanly) {
    const std::size_t reserved = stats().reserved_bytes;
    if (reserved > kSmallReservation)
        GTEST_SKIP() << "would commit " << (reserved >> 20) << " MiB; run with CHIMERA_HEAP_MB=64";
    errno = 0;
    EXPECT_EQ(chm_malloc(reserved + (std::size_t{1} << 20)), nullptr);
    EXPECT_EQ(errno, ENOMEM);
    // While the heap is full nothing else may allocate, the test included:
    // room for the pointers is taken first, results are checked afterwards.
    std::vector<void*> ps;
    ps.reserve(reserved >> 20);
    while (void* p = chm_malloc(std::size_t{1} << 20))
        ps.push_back(p);
    const int full_errno = errno;
    const struct chm_mem_stats full = stats();
    const int full_check = chm_mem_check();
    void* small = chm_malloc(64);  // still fits between the big blocks
    chm_free(small);
    for (void* p : ps)
        chm_free(p);
    EXPECT_EQ(full_errno, ENOMEM);
    EXPECT_EQ(full.committed_bytes, full.reserved_bytes);
    EXPECT_GT(ps.size(), (reserved >> 20) - 8);
    EXPECT_EQ(full_check, 0);
    EXPECT_NE(small, nullptr);
    EXPECT_EQ(chm_mem_check(), 0);
    EXPECT_GE(stats().largest_free, reserved - (std::size_t{2} << 20));
}

TEST(Heap, CApiErrorsAndSemantics) {
    // calloc zeroes memory that was dirty before.
    auto* dirty = static_cast<unsigned char*>(chm_malloc(4000));
    std::memset(dirty, 0xee, 4000);
    chm_free(dirty);
    auto* z = static_cast<unsigned char*>(chm_calloc(1000, 4));
    ASSERT_NE(z, nullptr);
    for (int i = 0; i < 4000; ++i)
        ASSERT_EQ(z[i], 0);
    errno = 0;
    EXPECT_EQ(chm_calloc(SIZE_MAX / 2, 3), nullptr);
    EXPECT_EQ(errno, ENOMEM);

    // realloc keeps contents; NULL acts as malloc; size 0 frees.
    for (int i = 0; i < 4000; ++i)
        z[i] = static_cast<unsigned char>(i);
    auto* r = static_cast<unsigned char*>(chm_realloc(z, 100000));
    ASSERT_NE(r, nullptr);
    for (int i = 0; i < 4000; ++i)
        ASSERT_EQ(r[i], static_cast<unsigned char>(i));
    EXPECT_GE(chm_malloc_usable_size(r), 100000u);
    EXPECT_EQ(chm_realloc(r, 0), nullptr);
    void* n = chm_realloc(nullptr, 10);
    EXPECT_NE(n, nullptr);
    errno = 0;
    EXPECT_EQ(chm_realloc(n, SIZE_MAX / 2), nullptr);
    EXPECT_EQ(errno, ENOMEM);
    EXPECT_GE(chm_malloc_usable_size(n), 10u);  // still valid

    // Pointers that are not ours.
    int on_stack = 0;
    const std::size_t invalid = stats().invalid_frees;
    errno = 0;
    EXPECT_EQ(chm_realloc(&on_stack, 10), nullptr);
    EXPECT_EQ(errno, EINVAL);
    chm_free(&on_stack);
    chm_free(n);
    chm_free(n);  // double free
    EXPECT_EQ(stats().invalid_frees, invalid + 3);
    EXPECT_EQ(chm_malloc_usable_size(&on_stack), 0u);
    EXPECT_EQ(chm_malloc_usable_size(nullptr), 0u);
    chm_free(nullptr);

    // memalign
    errno = 0;
    EXPECT_EQ(chm_memalign(3, 10), nullptr);
    EXPECT_EQ(errno, EINVAL);
    for (std::size_t a = 1; a <= (std::size_t{1} << 16); a <<= 1) {
        void* p = chm_memalign(a, 33);
        ASSERT_NE(p, nullptr);
        EXPECT_EQ(reinterpret_cast<std::uintptr_t>(p) % a, 0u);
        chm_free(p);
    }
    void* zero = chm_malloc(0);
    EXPECT_NE(zero, nullptr);
    chm_free(zero);
    EXPECT_EQ(chm_mem_stats(nullptr), -EINVAL);
    EXPECT_EQ(chm_mem_check(), 0);
}

TEST(Heap, CheckReportsCorruption) {
    void* a = chm_malloc(64);
    void* b = chm_malloc(64);
    auto* size_word = static_cast<std::size_t*>(b) - 1;
    const std::size_t saved = *size_word;
    *size_word = 0x12345670;
    EXPECT_EQ(chm_mem_check(), -EFAULT);
    CheckReport r;
    EXPECT_FALSE(heap_check(&r));
    ASSERT_NE(r.what, nullptr);
    std::printf("detected: %s\n", r.what);
    *size_word = saved;
    EXPECT_EQ(chm_mem_check(), 0);
    chm_free(a);
    chm_free(b);
}

bool in_code_range(const void* fn) {
    const CodeRange r = allocator_code_range();
    const auto a = reinterpret_cast<std::uintptr_t>(fn);
    return a >= r.lo && a < r.hi;
}

// The port keeps tasks from being preempted inside the allocator by its
// code range (mem_text.hpp): every entry point must lie in it.
TEST(Heap, AllocatorCodeIsOneRange) {
    const CodeRange r = allocator_code_range();
    ASSERT_LT(r.lo, r.hi);
#if defined(__SANITIZE_ADDRESS__)  // AddressSanitizer owns the C library's names (meson b_sanitize)
    for (const void* fn : {reinterpret_cast<const void*>(&chm_malloc),
#else
    for (const void* fn : {reinterpret_cast<const void*>(&malloc),
                           reinterpret_cast<const void*>(&free),
                           reinterpret_cast<const void*>(&calloc),
                           reinterpret_cast<const void*>(&realloc),
                           reinterpret_cast<const void*>(&posix_memalign),
                           reinterpret_cast<const void*>(&chm_malloc),
#endif
                           reinterpret_cast<const void*>(&chm_free),
                           reinterpret_cast<const void*>(&chm_mem_check),
                           reinterpret_cast<const void*>(&heap_allocate),
                           reinterpret_cast<const void*>(&heap_free),
                           reinterpret_cast<const void*>(&chm_heap_set_lock_hooks)})
        EXPECT_TRUE(in_code_range(fn)) << fn;
    EXPECT_FALSE(in_code_range(reinterpret_cast<const void*>(&in_code_range)));
}

// The kernel's heap lock hooks run inside mallocs the C library makes
// holding its own locks: they must be allocator code, never preempted
// (mem_text.hpp). Out of the section, a tick at their last instructions
// lost stdio lines under qemu-aarch64 (CLibraryIsSafeUnderPreemption, 9
// runs in 60); this holds on every target whatever the timing.
void not_a_hook() {}

TEST(Heap, TheKernelsLockHooksAreAllocatorCode) {
    chm_kernel_config_t c;
    chm_kernel_config_init(&c);  // the real clock: the hooks are installed
    ASSERT_EQ(chm_kernel_init(&c), 0);
    chm_heap_hook_fn enter = nullptr, leave = nullptr;
    heap_lock_hooks(&enter, &leave);
    chm_kernel_fini();
    ASSERT_NE(enter, nullptr);
    ASSERT_NE(leave, nullptr);
    EXPECT_TRUE(in_code_range(reinterpret_cast<const void*>(enter))) << "heap_enter outside chm_mem_text";
    EXPECT_TRUE(in_code_range(reinterpret_cast<const void*>(leave))) << "heap_leave outside chm_mem_text";
    chm_heap_hook_fn after_enter = &not_a_hook, after_leave = &not_a_hook;
    heap_lock_hooks(&after_enter, &after_leave);
    EXPECT_EQ(after_enter, nullptr) << "chm_kernel_fini leaves no hook behind";
    EXPECT_EQ(after_leave, nullptr);
}

std::atomic<int> g_enters{0};
std::atomic<int> g_leaves{0};
std::atomic<int> g_depth{0};
std::atomic<bool> g_nested{false};
void on_enter() {
    ++g_enters;
    if (++g_depth != 1)
        g_nested = true;
}
void on_leave() {
    ++g_leaves;
    --g_depth;
}

TEST(Heap, LockHooksBracketEveryCall) {
    chm_heap_set_lock_hooks(on_enter, on_leave);
    void* p = chm_malloc(10);
    p = chm_realloc(p, 1000);
    chm_free(p);
    (void)chm_mem_check();
    EXPECT_EQ(g_enters.load(), 4);
    EXPECT_EQ(g_leaves.load(), 4);
    // fork() holds the heap lock across the system call: bracketed too.
    const pid_t pid = fork();
    if (pid == 0)
        _exit(0);
    ASSERT_GT(pid, 0);
    chm_heap_set_lock_hooks(nullptr, nullptr);
    int status = 0;
    EXPECT_EQ(waitpid(pid, &status, 0), pid);
    EXPECT_GE(g_enters.load(), 5);  // other fork handlers may allocate too
    EXPECT_EQ(g_enters.load(), g_leaves.load());
    EXPECT_FALSE(g_nested.load());
    const int enters = g_enters.load();
    chm_free(chm_malloc(10));
    EXPECT_EQ(g_enters.load(), enters);
}

TEST(Heap, PrecommitMakesLaterAllocationsCommitFree) {
    if (stats().reserved_bytes > kSmallReservation)
        GTEST_SKIP() << "run with CHIMERA_HEAP_MB=64";
    ASSERT_TRUE(heap_precommit(std::size_t{40} << 20));
    const struct chm_mem_stats s = stats();
    EXPECT_GE(s.committed_bytes, std::size_t{40} << 20);
    std::vector<void*> ps;
    for (int i = 0; i < 30; ++i)
        ps.push_back(chm_malloc(std::size_t{1} << 20));
    EXPECT_EQ(stats().commits, s.commits);
    for (void* p : ps)
        chm_free(p);
    EXPECT_FALSE(heap_precommit(stats().reserved_bytes + 1));
}

// Threads allocate and free, some blocks cross to another thread to be
// freed there, while the main thread forks: each child must find the heap
// usable (the lock was not left held by a thread that does not exist there).
TEST(Heap, ForkWhileOtherThreadsAllocate) {
    std::atomic<bool> stop{false};
    std::vector<std::thread> threads;
    for (int i = 0; i < 2; ++i)
        threads.emplace_back([&stop] {
            while (!stop.load(std::memory_order_relaxed))
                chm_free(chm_malloc(128));
        });
    for (int i = 0; i < 20; ++i) {
        const pid_t pid = fork();
        ASSERT_GE(pid, 0);
        if (pid == 0) {
            void* p = chm_malloc(1000);
            const bool ok = p && chm_mem_check() == 0;
            chm_free(p);
            _exit(ok ? 0 : 1);
        }
        int status = 0;
        ASSERT_EQ(waitpid(pid, &status, 0), pid);
        EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "child " << i;
    }
    stop = true;
    for (auto& t : threads)
        t.join();
    EXPECT_EQ(chm_mem_check(), 0);
}

TEST(HeapStress, FourThreads) {
    constexpr int kThreads = 4;
    const int ops = std::getenv("CHIMERA_MEM_STRESS_OPS") ? 50'000 : 250'000;
    constexpr std::size_t kSlots = 512;
    constexpr std::size_t kMailboxes = 64;
    // Blocks handed between threads: a thread frees what another allocated.
    std::atomic<void*> mailbox[kMailboxes] = {};
    std::atomic<int> errors{0};
    const std::size_t invalid_before = stats().invalid_frees;

    auto worker = [&](int id) {
        struct Slot {
            void* p = nullptr;
            std::size_t n = 0;
            std::uint32_t tag = 0;
        };
        std::vector<Slot> slots(kSlots);
        test::Rng rng(1000 + static_cast<std::uint64_t>(id));
        std::uint32_t tag = static_cast<std::uint32_t>(id) << 24;
        for (int op = 0; op < ops; ++op) {
            Slot& s = slots[rng.range(0, kSlots - 1)];
            const unsigned what = static_cast<unsigned>(rng.next() % 100);
            if (!s.p) {
                s.n = rng.chance(90) ? rng.range(1, 512) : rng.range(513, 65536);
                s.p = what < 10 ? chm_memalign(64, s.n) : chm_malloc(s.n);
                if (!s.p) {
                    ++errors;
                    continue;
                }
                s.tag = ++tag;
                test::fill(s.p, s.n, s.tag);
            } else if (what < 50) {
                if (!test::verify(s.p, s.n, s.n, s.tag))
                    ++errors;
                chm_free(s.p);
                s = {};
            } else if (what < 75) {
                const std::size_t n = rng.range(1, 4096);
                void* q = chm_realloc(s.p, n);
                if (!q || !test::verify(q, n < s.n ? n : s.n, s.n, s.tag)) {
                    ++errors;
                    continue;
                }
                s = {q, n, ++tag};
                test::fill(s.p, s.n, s.tag);
            } else {
                // Post the block (contents no longer tracked) and free
                // whatever another thread posted before.
                void* old = mailbox[rng.range(0, kMailboxes - 1)].exchange(s.p);
                chm_free(old);
                s = {};
            }
        }
        for (Slot& s : slots) {
            if (s.p && !test::verify(s.p, s.n, s.n, s.tag))
                ++errors;
            chm_free(s.p);
        }
    };
    std::vector<std::thread> threads;
    for (int i = 0; i < kThreads; ++i)
        threads.emplace_back(worker, i);
    for (auto& t : threads)
        t.join();
    for (auto& m : mailbox)
        chm_free(m.exchange(nullptr));
    // (No exact block count afterwards: the C library keeps per-thread
    // allocations of finished threads with their cached stacks.)
    EXPECT_EQ(errors.load(), 0);
    EXPECT_EQ(chm_mem_check(), 0);
    EXPECT_EQ(stats().invalid_frees, invalid_before);
}

}  // namespace
}  // namespace chm::mem
