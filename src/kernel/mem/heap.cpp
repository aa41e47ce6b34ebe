// The process heap: reservation, chunked commit, the lock and its hooks.
// See heap.hpp for the design. Everything here runs before main as readily
// as after it, so the state is constant-initialised and nothing in this file
// allocates, throws or needs a constructor to have run.

// No PLT stubs: they would lie in the executable's preemptible code (see
// mem_text.hpp). Calls into the C library go through the GOT instead.
#pragma GCC optimize("no-plt")
#if defined(__aarch64__)
#pragma GCC target("no-outline-atomics")  // atomics inline, not calls into the program's text
#endif

#include "kernel/mem/heap.hpp"
#include "kernel/mem/mem_text.hpp"

#include <cerrno>
#include <cstdint>
#include <cstdlib>
#include <cstring>

#include <linux/futex.h>
#include <pthread.h>
#include <sys/mman.h>
#include <sys/syscall.h>
#include <unistd.h>

#include "kernel/mem/tlsf_block.hpp"
#include "port.hpp"  // relax(): the port's spin-wait hint

#ifndef MADV_POPULATE_WRITE
#define MADV_POPULATE_WRITE 23  // Linux 5.14, same value on every architecture
#endif

namespace chm::mem {

namespace {

// Drepper's three-state futex mutex (0 free, 1 held, 2 held with sleepers),
// with a short spin first: heap critical sections are a few hundred
// nanoseconds, far less than a futex sleep and wake.
class HeapLock {
public:
    constexpr HeapLock() = default;

    CHM_MEM_TEXT void lock() {
        std::uint32_t expected = 0;
        if (cas(expected, 1))
            return;
        for (int i = 0; i < kSpins; ++i) {
            chm::port::relax();  // always inlined: stays in chm_mem_text
            expected = 0;
            if (__atomic_load_n(&word_, __ATOMIC_RELAXED) == 0 && cas(expected, 1))
                return;
        }
        while (__atomic_exchange_n(&word_, 2u, __ATOMIC_ACQUIRE) != 0)
            syscall(SYS_futex, &word_, FUTEX_WAIT_PRIVATE, 2u, nullptr, nullptr, 0);
    }

    CHM_MEM_TEXT void unlock() {
        if (__atomic_exchange_n(&word_, 0u, __ATOMIC_RELEASE) == 2)
            syscall(SYS_futex, &word_, FUTEX_WAKE_PRIVATE, 1, nullptr, nullptr, 0);
    }

    // In a fork child only the forking thread exists, and it held the lock.
    CHM_MEM_TEXT void reset_in_child() { __atomic_store_n(&word_, 0u, __ATOMIC_RELAXED); }

private:
    static constexpr int kSpins = 100;
    CHM_MEM_TEXT bool cas(std::uint32_t& expected, std::uint32_t desired) {
        return __atomic_compare_exchange_n(&word_, &expected, desired, false,
                                           __ATOMIC_ACQUIRE, __ATOMIC_RELAXED);
    }
    alignas(4) std::uint32_t word_ = 0;
};

struct Heap {
    HeapLock lock;
    // Written under the lock, read without it by heap_owns().
    std::uintptr_t base = 0;
    std::size_t committed = 0;
    std::size_t reserved = 0;
    std::size_t commits = 0;
    std::size_t foreign_frees = 0;
    bool init_failed = false;
    Tlsf tlsf;
};

constinit Heap g_heap;
constinit chm_heap_hook_fn g_enter = nullptr;
constinit chm_heap_hook_fn g_leave = nullptr;

// __atomic builtins, not std::atomic, and forced inline: no helper may land
// outside chm_mem_text, even unoptimised (see mem_text.hpp).
template <typename T>
CHM_MEM_INLINE inline T load_acquire(const T& v) {
    return __atomic_load_n(&v, __ATOMIC_ACQUIRE);
}
template <typename T>
CHM_MEM_INLINE inline void store_release(T& v, T x) {
    __atomic_store_n(&v, x, __ATOMIC_RELEASE);
}

// Holds the heap lock for one heap call, with the preemption hooks around.
class Guard {
public:
    CHM_MEM_TEXT Guard() : leave_(load_acquire(g_leave)) {
        if (auto enter = load_acquire(g_enter))
            enter();
        g_heap.lock.lock();
    }
    CHM_MEM_TEXT ~Guard() {
        g_heap.lock.unlock();
        if (leave_)
            leave_();
    }
    Guard(const Guard&) = delete;
    Guard& operator=(const Guard&) = delete;

private:
    chm_heap_hook_fn leave_;
};

// CHIMERA_HEAP_MB as a number of bytes. Parsed by hand: this may run before
// the C library has finished initialising (locale, stdio).
CHM_MEM_TEXT std::size_t requested_reservation() {
    const char* s = std::getenv("CHIMERA_HEAP_MB");
    std::size_t mb = 0;
    if (s) {
        for (; *s >= '0' && *s <= '9'; ++s) {
            if (mb > (SIZE_MAX >> 20) / 10)
                return SIZE_MAX & ~(kHeapChunk - 1);  // absurdly large: let mmap decide
            mb = mb * 10 + static_cast<std::size_t>(*s - '0');
        }
    }
    if (mb == 0)
        mb = kHeapDefaultMb;
    if (mb > (SIZE_MAX >> 20))
        return SIZE_MAX & ~(kHeapChunk - 1);
    return mb << 20;
}

// Touch the pages now so the first allocations from them do not fault.
CHM_MEM_TEXT void prefault(char* at, std::size_t bytes) {
    // One system call where the kernel supports it; the stores make sure of
    // it elsewhere (older kernels, emulators that accept and ignore advice)
    // and cost a few nanoseconds a page when the pages are already there.
    madvise(at, bytes, MADV_POPULATE_WRITE);
    const auto page = static_cast<std::size_t>(sysconf(_SC_PAGESIZE));
    for (std::size_t off = 0; off < bytes; off += page)
        *reinterpret_cast<volatile char*>(at + off) = 0;
}

// Commit at least `bytes` more (whole chunks, or what is left of the
// reservation) and give them to the allocator. Heap lock held.
CHM_MEM_TEXT bool commit_chunks(std::size_t bytes) {
    Heap& h = g_heap;
    const std::size_t done = load_acquire(h.committed);
    const std::size_t left = h.reserved - done;
    if (bytes > left)
        return false;
    std::size_t n = (bytes + kHeapChunk - 1) & ~(kHeapChunk - 1);
    if (n > left || n < bytes)
        n = left;
    if (n == 0)
        return false;
    char* at = reinterpret_cast<char*>(load_acquire(h.base)) + done;
    const int saved_errno = errno;
    const bool ok = mprotect(at, n, PROT_READ | PROT_WRITE) == 0;
    if (ok)
        prefault(at, n);
    errno = saved_errno;
    if (!ok || !h.tlsf.add_pool(at, n))
        return false;
    store_release(h.committed, done + n);
    ++h.commits;
    return true;
}

// Reserve and commit the first chunk on first use. Heap lock held.
CHM_MEM_TEXT bool ensure_ready() {
    Heap& h = g_heap;
    if (load_acquire(h.base))
        return true;
    if (h.init_failed)
        return false;
    const int saved_errno = errno;
    std::size_t want = requested_reservation();
    void* p = MAP_FAILED;
    // A 32-bit process may not find 1 GiB of contiguous address space:
    // halve until it fits, down to one chunk.
    for (; want >= kHeapChunk; want = (want / 2) & ~(kHeapChunk - 1)) {
        p = mmap(nullptr, want, PROT_NONE, MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
        if (p != MAP_FAILED)
            break;
    }
    errno = saved_errno;
    if (p == MAP_FAILED) {
        h.init_failed = true;
        return false;
    }
    h.reserved = want;
    store_release(h.base, reinterpret_cast<std::uintptr_t>(p));
    if (!commit_chunks(kHeapChunk)) {
        h.init_failed = true;  // base stays set: heap_owns() is harmless
        return false;
    }
    return true;
}

// Commit enough that an allocation of `size` bytes aligned to `align` finds
// a block: the new chunk joins the free tail, and a block of this size is on
// a list every block of which fits (TLSF rounds the request up by 1/32).
// Heap lock held.
CHM_MEM_TEXT bool grow_for(std::size_t size, std::size_t align) {
    if (size > Tlsf::kMaxRequest || align > Tlsf::kMaxRequest)
        return false;
    const std::size_t need = size + (size >> Tlsf::kSlLog2) + align + 4 * Tlsf::kMinBlock;
    return commit_chunks(need);
}

// A pointer the allocator may inspect without leaving committed memory.
// Heap lock held (the header it reads must not change under it).
CHM_MEM_TEXT bool inspectable(const void* p) {
    const auto a = reinterpret_cast<std::uintptr_t>(p);
    const std::uintptr_t base = load_acquire(g_heap.base);
    const std::size_t committed = load_acquire(g_heap.committed);
    if (a < base + Tlsf::kHeader || a - base >= committed)
        return false;
    // Its successor's header must be committed too, whatever the size word
    // says: that header ends at p + size.
    const std::size_t size = Tlsf::Block::from_payload(p)->size();
    return size <= committed && a + size <= base + committed;
}

// fork() holds the lock across the system call, so the hooks bracket it as
// they bracket any heap call: the kernel thread is not preempted (and no
// task of it calls malloc) while it forks.
chm_heap_hook_fn g_fork_leave = nullptr;

CHM_MEM_TEXT void atfork_prepare() {
    g_fork_leave = load_acquire(g_leave);
    if (auto enter = load_acquire(g_enter))
        enter();
    g_heap.lock.lock();
}
CHM_MEM_TEXT void atfork_parent() {
    g_heap.lock.unlock();
    if (g_fork_leave)
        g_fork_leave();
}
CHM_MEM_TEXT void atfork_child() {
    g_heap.lock.reset_in_child();
    if (g_fork_leave)
        g_fork_leave();
}

// Runs during static initialisation. pthread_atfork may itself allocate,
// which is fine: the lock is not held here. Registering early makes our
// prepare handler run late (they run in reverse order), after the prepare
// handlers of later-loaded code, which may still allocate.
[[gnu::constructor(101)]] CHM_MEM_TEXT void register_atfork() {
    pthread_atfork(atfork_prepare, atfork_parent, atfork_child);
}

}  // namespace

CHM_MEM_TEXT void* heap_allocate(std::size_t size) {
    Guard g;
    if (!ensure_ready())
        return nullptr;
    void* p = g_heap.tlsf.allocate(size);
    if (!p && grow_for(size, Tlsf::kAlign))
        p = g_heap.tlsf.allocate(size);
    return p;
}

CHM_MEM_TEXT void* heap_allocate_zeroed(std::size_t n, std::size_t size) {
    std::size_t bytes = 0;
    if (__builtin_mul_overflow(n, size, &bytes))
        return nullptr;
    void* p = heap_allocate(bytes);
    // Freed blocks are reused as they are, so zero every time.
    if (p)
        std::memset(p, 0, bytes);
    return p;
}

CHM_MEM_TEXT void* heap_allocate_aligned(std::size_t align, std::size_t size) {
    Guard g;
    if (!ensure_ready())
        return nullptr;
    void* p = g_heap.tlsf.allocate_aligned(align, size);
    if (!p && align && !(align & (align - 1)) && grow_for(size, align))
        p = g_heap.tlsf.allocate_aligned(align, size);
    return p;
}

CHM_MEM_TEXT void* heap_reallocate(void* p, std::size_t size, bool* bad_pointer) {
    if (bad_pointer)
        *bad_pointer = false;
    if (!p)
        return heap_allocate(size);
    Guard g;
    Tlsf& t = g_heap.tlsf;
    if (!inspectable(p)) {
        ++g_heap.foreign_frees;
        if (bad_pointer)
            *bad_pointer = true;
        return nullptr;
    }
    if (!t.is_allocated(p)) {
        t.free(p);  // refused: counts it as an invalid free
        if (bad_pointer)
            *bad_pointer = true;
        return nullptr;
    }
    if (size == 0) {
        t.free(p);
        return nullptr;
    }
    void* q = t.reallocate(p, size);
    if (!q && grow_for(size, Tlsf::kAlign))
        q = t.reallocate(p, size);
    return q;
}

CHM_MEM_TEXT bool heap_free(void* p) {
    if (!p)
        return true;
    Guard g;
    if (!inspectable(p)) {
        ++g_heap.foreign_frees;
        return false;
    }
    return g_heap.tlsf.free(p);
}

CHM_MEM_TEXT std::size_t heap_usable_size(const void* p) {
    if (!p)
        return 0;
    Guard g;
    if (!inspectable(p) || !g_heap.tlsf.is_allocated(p))
        return 0;
    return Tlsf::usable_size(p);
}

CHM_MEM_TEXT bool heap_owns(const void* p) {
    const auto a = reinterpret_cast<std::uintptr_t>(p);
    const std::uintptr_t base = load_acquire(g_heap.base);
    return base && a >= base && a - base < load_acquire(g_heap.committed);
}

CHM_MEM_TEXT bool heap_check(CheckReport* report) {
    Guard g;
    if (!load_acquire(g_heap.base))
        return true;
    return g_heap.tlsf.check(report);
}

CHM_MEM_TEXT HeapStats heap_stats() {
    Guard g;
    HeapStats s;
    s.reserved_bytes = g_heap.reserved;
    s.committed_bytes = load_acquire(g_heap.committed);
    s.commits = g_heap.commits;
    s.foreign_frees = g_heap.foreign_frees;
    s.tlsf = g_heap.tlsf.stats();
    return s;
}

CHM_MEM_TEXT bool heap_precommit(std::size_t bytes) {
    Guard g;
    if (!ensure_ready())
        return false;
    const std::size_t done = load_acquire(g_heap.committed);
    return bytes <= done || commit_chunks(bytes - done);
}

// The linker defines these for a section whose name is an identifier.
extern "C" {
extern const char __start_chm_mem_text[] __attribute__((weak, visibility("hidden")));
extern const char __stop_chm_mem_text[] __attribute__((weak, visibility("hidden")));
}

CodeRange allocator_code_range() {
    return {reinterpret_cast<std::uintptr_t>(__start_chm_mem_text),
            reinterpret_cast<std::uintptr_t>(__stop_chm_mem_text)};
}

CHM_MEM_TEXT void heap_lock_hooks(chm_heap_hook_fn* enter, chm_heap_hook_fn* leave) {
    *enter = load_acquire(g_enter);
    *leave = load_acquire(g_leave);
}

}  // namespace chm::mem

extern "C" CHM_MEM_TEXT void chm_heap_set_lock_hooks(chm_heap_hook_fn enter, chm_heap_hook_fn leave) {
    chm::mem::store_release(chm::mem::g_enter, enter);
    chm::mem::store_release(chm::mem::g_leave, leave);
}
