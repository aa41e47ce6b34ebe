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

void stacks_release(unsigned char* lo, std::size_t size, std::size_t dirty) {
    // Re-zero what the task dirtied so the next owner's high water is exact.
    if (dirty > size) dirty = size;
    std::memset(lo + size - dirty, 0, dirty);
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

std::size_t stack_round(std::size_t size) {
    const std::size_t p = page_size();
    return (size + p - 1) / p * p;
}

}  // namespace chm::kernel

namespace chm::kernel {

// Cheap bound for stacks_release: from the top down to the first 512-byte
// run of zeros, aligned to 64 bytes (a cache line: the eight words of a
// line are ORed, one branch per line instead of per word). A zero hole
// deeper in the stack leaves stale bytes below it, which only makes the
// next owner's high water conservative (larger). Stacks are page-sized, so
// the top is line-aligned.
std::size_t stack_dirty_estimate(const Tcb* t) {
    constexpr int kWords = 8, kZeroLines = 8;
    const auto* top = reinterpret_cast<const std::uint64_t*>(t->stack_lo + t->stack_size);
    const auto* lo = reinterpret_cast<const std::uint64_t*>(t->stack_lo);
    const auto* w = top;
    int zeros = 0;
    while (w - lo >= kWords && zeros < kZeroLines) {
        w -= kWords;
        const std::uint64_t any = w[0] | w[1] | w[2] | w[3] | w[4] | w[5] | w[6] | w[7];
        zeros = any ? 0 : zeros + 1;
    }
    return std::size_t(reinterpret_cast<const unsigned char*>(top) -
                       reinterpret_cast<const unsigned char*>(w));
}

}  // namespace chm::kernel
