// The process heap: one TLSF allocator over one large virtual reservation,
// shared by every thread of the process (the kernel thread's tasks, helper
// threads, and — through malloc_interpose.cpp — the C and C++ libraries).
//
// The reservation (CHIMERA_HEAP_MB, default 1024 MiB, PROT_NONE and
// MAP_NORESERVE, so it costs address space only) is committed from its start
// in kHeapChunk pieces, each made readable/writable and pre-faulted before
// the allocator sees it, and appended to the one pool. An allocation is
// therefore the bounded TLSF path unless the pool is exhausted, when the one
// unlucky call commits a chunk (a system call and page faults). The kernel
// can commit ahead with heap_precommit() so its real-time phase never does.
// Memory is never returned to the system: determinism over footprint.
//
// Locking: a spin-then-futex lock, taken for a bounded TLSF operation (or a
// commit). Optional hooks run around it so the kernel can mask preemption of
// its green threads while one of them holds the lock: otherwise a task
// preempted inside malloc would deadlock the next task on that thread that
// calls malloc. The heap must not be used from a signal handler.
//
// Initialisation is lazy and needs no constructor: the first call (which may
// come from the dynamic loader or a static constructor, before main) reserves
// and commits. fork() is safe: the lock is taken around it (pthread_atfork).
#pragma once

#include <cstddef>

#include "kernel/mem/tlsf.hpp"

namespace chm::mem {

inline constexpr std::size_t kHeapChunk = std::size_t{4} << 20;
inline constexpr std::size_t kHeapDefaultMb = 1024;

struct HeapStats {
    std::size_t reserved_bytes = 0;   // virtual reservation
    std::size_t committed_bytes = 0;  // of which usable (handed to the allocator)
    std::size_t commits = 0;          // chunk commits so far
    std::size_t foreign_frees = 0;    // frees of pointers outside the heap (ignored)
    TlsfStats tlsf;
};

// All of these may be called from any thread, before main included.
// They return nullptr / false on failure and never set errno; the C API
// (mem_api.cpp) and the malloc family (malloc_interpose.cpp) do that.
void* heap_allocate(std::size_t size);
void* heap_allocate_aligned(std::size_t align, std::size_t size);  // align: power of two
// nullptr p allocates; size 0 frees and returns nullptr; a pointer that is
// not an allocated block of this heap returns nullptr, changes nothing and
// sets *bad_pointer (when given) to true.
void* heap_reallocate(void* p, std::size_t size, bool* bad_pointer = nullptr);
// false when p (non-null) is not an allocated block of this heap; then
// nothing is freed.
bool heap_free(void* p);
// Usable bytes of the allocated block p, 0 for nullptr or a foreign pointer.
std::size_t heap_usable_size(const void* p);
// Is p inside the committed part of the heap? O(1), lock-free.
bool heap_owns(const void* p);
// Full consistency walk under the lock (O(blocks)); true if the heap has not
// been used yet.
bool heap_check(CheckReport* report = nullptr);
HeapStats heap_stats();
// Commit until at least `bytes` are committed in total. False if the
// reservation is smaller or the system refuses.
bool heap_precommit(std::size_t bytes);

}  // namespace chm::mem

extern "C" {
// Preemption hooks, called on the calling thread: `enter` before the heap
// lock is taken, `leave` after it is released, once each per heap call.
// The kernel installs a pair that masks preemption when called on the kernel
// thread (and does nothing on other threads). Install them before a second
// thread uses the heap, or while no thread is inside it; nullptr removes a
// hook. The hooks must not use the heap.
typedef void (*chm_heap_hook_fn)(void);
void chm_heap_set_lock_hooks(chm_heap_hook_fn enter, chm_heap_hook_fn leave);
}
