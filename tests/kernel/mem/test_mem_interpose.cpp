// A program linked with malloc_interpose.cpp: its malloc family, the C
// library's internal allocations, operator new and the C++ library's
// containers and threads all run on the Chimera heap, from before main on.
#include <gtest/gtest.h>

#include <dlfcn.h>
#include <malloc.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "chimera/mem.h"
#include "kernel/mem/heap.hpp"
#include "mem_test_util.hpp"

namespace chm::mem {
namespace {

// Runs during static initialisation, before main and before gtest.
struct BeforeMain {
    void* p = nullptr;
    bool owned = false;
    std::size_t commits = 0;
    BeforeMain() {
        p = std::malloc(123);
        owned = heap_owns(p);
        commits = heap_stats().commits;
    }
};
const BeforeMain g_before_main;

std::size_t used_bytes() { return heap_stats().tlsf.used_bytes; }

TEST(Interpose, MallocBeforeMainCameFromTheHeap) {
    ASSERT_NE(g_before_main.p, nullptr);
    EXPECT_TRUE(g_before_main.owned);
    EXPECT_GE(g_before_main.commits, 1u);
    std::free(g_before_main.p);
}

TEST(Interpose, TheMallocFamilyIsOurs) {
    // The symbol the dynamic linker resolves for everyone is this program's.
    EXPECT_EQ(dlsym(RTLD_DEFAULT, "malloc"), reinterpret_cast<void*>(&malloc));
    EXPECT_EQ(dlsym(RTLD_DEFAULT, "free"), reinterpret_cast<void*>(&free));

    const std::size_t before = used_bytes();
    void* p = std::malloc(100000);
    ASSERT_NE(p, nullptr);
    EXPECT_TRUE(heap_owns(p));
    EXPECT_GE(used_bytes(), before + 100000);
    std::free(p);
    EXPECT_LT(used_bytes(), before + 100000);

    // The C library's own allocations (strdup, stdio buffers) too.
    char* s = strdup("chimera");
    EXPECT_TRUE(heap_owns(s));
    std::free(s);
    FILE* f = tmpfile();
    ASSERT_NE(f, nullptr);
    std::fputs("hello", f);
    std::fclose(f);
    EXPECT_EQ(heap_stats().foreign_frees, 0u);  // nobody freed memory we never gave
}

TEST(Interpose, CallocReallocAndFriends) {
    auto* dirty = static_cast<unsigned char*>(std::malloc(5000));
    std::memset(dirty, 0xcd, 5000);
    std::free(dirty);
    auto* z = static_cast<unsigned char*>(std::calloc(5, 1000));
    ASSERT_NE(z, nullptr);
    for (int i = 0; i < 5000; ++i)
        ASSERT_EQ(z[i], 0) << i;
    errno = 0;
    volatile std::size_t huge = SIZE_MAX / 4;  // hidden from the compiler's own size check
    EXPECT_EQ(std::calloc(huge, 8), nullptr);
    EXPECT_EQ(errno, ENOMEM);

    for (int i = 0; i < 5000; ++i)
        z[i] = static_cast<unsigned char>(i * 3);
    auto* r = static_cast<unsigned char*>(std::realloc(z, 50000));
    ASSERT_NE(r, nullptr);
    for (int i = 0; i < 5000; ++i)
        ASSERT_EQ(r[i], static_cast<unsigned char>(i * 3));
    r = static_cast<unsigned char*>(std::realloc(r, 10));
    EXPECT_EQ(r[9], static_cast<unsigned char>(27));
    EXPECT_GE(malloc_usable_size(r), 10u);
    EXPECT_EQ(malloc_usable_size(nullptr), 0u);
    EXPECT_EQ(std::realloc(r, 0), nullptr);  // glibc semantics: frees
    void* n = std::realloc(nullptr, 32);
    EXPECT_TRUE(heap_owns(n));
    std::free(n);

    void* p = nullptr;
    EXPECT_EQ(posix_memalign(&p, 3, 10), EINVAL);
    EXPECT_EQ(posix_memalign(&p, 0, 10), EINVAL);
    EXPECT_EQ(posix_memalign(&p, sizeof(void*) / 2, 10), EINVAL);
    EXPECT_EQ(posix_memalign(&p, 48, 10), EINVAL);
    EXPECT_EQ(p, nullptr);  // untouched on error
    ASSERT_EQ(posix_memalign(&p, 256, 10), 0);
    EXPECT_EQ(reinterpret_cast<std::uintptr_t>(p) % 256, 0u);
    EXPECT_TRUE(heap_owns(p));
    std::free(p);

    const auto page = static_cast<std::uintptr_t>(sysconf(_SC_PAGESIZE));
    void* a = aligned_alloc(1024, 2048);
    void* m = memalign(64, 100);
    void* m3 = memalign(24, 100);  // glibc rounds the alignment up to 32
    void* v = valloc(100);
    void* pv = pvalloc(100);
    for (void* q : {a, m, m3, v, pv}) {
        ASSERT_NE(q, nullptr);
        EXPECT_TRUE(heap_owns(q));
    }
    EXPECT_EQ(reinterpret_cast<std::uintptr_t>(a) % 1024, 0u);
    EXPECT_EQ(reinterpret_cast<std::uintptr_t>(m) % 64, 0u);
    EXPECT_EQ(reinterpret_cast<std::uintptr_t>(m3) % 32, 0u);
    EXPECT_EQ(reinterpret_cast<std::uintptr_t>(v) % page, 0u);
    EXPECT_EQ(reinterpret_cast<std::uintptr_t>(pv) % page, 0u);
    EXPECT_GE(malloc_usable_size(pv), page);
    errno = 0;
    EXPECT_EQ(aligned_alloc(3, 10), nullptr);
    EXPECT_EQ(errno, EINVAL);
    for (void* q : {a, m, m3, v, pv})
        std::free(q);
    EXPECT_EQ(chm_mem_check(), 0);
}

struct alignas(256) Overaligned {
    char bytes[256];
};

TEST(Interpose, OperatorNewAndContainers) {
    auto owned = std::make_unique<int>(7);
    EXPECT_TRUE(heap_owns(owned.get()));
    auto* big = new Overaligned[3];  // aligned operator new
    EXPECT_TRUE(heap_owns(big));
    EXPECT_EQ(reinterpret_cast<std::uintptr_t>(big) % 256, 0u);
    delete[] big;

    const std::size_t before = used_bytes();
    {
        std::vector<std::string> words;
        std::map<int, std::string> index;
        for (int i = 0; i < 20000; ++i) {
            words.push_back("word number " + std::to_string(i) + " long enough for the heap");
            index[i] = words.back();
        }
        EXPECT_TRUE(heap_owns(words.data()));
        EXPECT_TRUE(heap_owns(words[123].data()));
        EXPECT_GT(used_bytes(), before + 20000 * 40);
        EXPECT_EQ(index[19999], words[19999]);
    }
    EXPECT_LT(used_bytes(), before + 4096);
    EXPECT_EQ(chm_mem_check(), 0);
}

TEST(Interpose, ThreadsRunOnTheHeap) {
    constexpr int kThreads = 4;
    std::vector<std::thread> threads;
    std::vector<std::size_t> sums(kThreads);
    std::vector<char> owned(kThreads);  // not vector<bool>: one byte per writer
    for (int t = 0; t < kThreads; ++t)
        threads.emplace_back([t, &sums, &owned] {
            std::vector<std::unique_ptr<std::string>> v;
            test::Rng rng(static_cast<std::uint64_t>(t));
            for (int i = 0; i < 50000; ++i) {
                v.push_back(std::make_unique<std::string>(rng.range(1, 200), 'a' + t));
                if (v.size() > 100)
                    v.erase(v.begin() + static_cast<long>(rng.range(0, v.size() - 1)));
            }
            owned[t] = heap_owns(v.data()) && heap_owns(v.back().get());
            for (auto& s : v)
                sums[t] += s->size();
        });
    for (auto& th : threads)
        th.join();
    for (int t = 0; t < kThreads; ++t) {
        EXPECT_TRUE(owned[t]) << t;
        EXPECT_GT(sums[t], 0u);
    }
    EXPECT_EQ(chm_mem_check(), 0);
    EXPECT_EQ(heap_stats().foreign_frees, 0u);
}

}  // namespace
}  // namespace chm::mem
