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
// commit). A green thread must never be switched out inside the allocator:
// holding this lock (the next task on its thread to call malloc would
// deadlock), or merely inside a malloc that the C library called with one of
// its own locks held. The allocator's code is therefore kept in one range,
// allocator_code_range(), that the port must exclude from preemption like
// the C library (mem_text.hpp). Optional hooks also run around the lock (for
// ports that mask preemption instead). The heap must not be used from a
// signal handler, and so not from the kernel's tick work.
//
// Initialisation is lazy and needs no constructor: the first call (which may
// come from the dynamic loader or a static constructor, before main) reserves
// and commits. fork() is safe: the lock is taken around it (pthread_atfork).
#pragma once

#include <cstddef>
#include <cstdint>

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
// n * size bytes, zeroed (calloc); nullptr when the product overflows too.
void* heap_allocate_zeroed(std::size_t n, std::size_t size);
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

// The allocator's machine code, [lo, hi): the section chm_mem_text of the
// object the allocator is linked into (mem_text.hpp says why). The port must
// treat it like the C library's code and never preempt a task there.
struct CodeRange {
    std::uintptr_t lo = 0;
    std::uintptr_t hi = 0;
};
CodeRange allocator_code_range();

}  // namespace chm::mem

extern "C" {
// Preemption hooks, called on the calling thread: `enter` before the heap
// lock is taken, `leave` after it is released, once each per heap call (and
// around fork, which holds the lock). The kernel may install a pair that
// masks preemption when called on the kernel thread. `leave` must not switch
// tasks (for instance by taking a tick that arrived while masked): its
// caller may be the C library with a lock held; leave such a tick pending
// for the port's deferral to deliver at a preemptible point. The hooks must
// not use the heap and should themselves be non-preemptible code. Install
// them before a second thread uses the heap, or while no thread is inside
// it; nullptr removes a hook.
typedef void (*chm_heap_hook_fn)(void);
void chm_heap_set_lock_hooks(chm_heap_hook_fn enter, chm_heap_hook_fn leave);
}

namespace chm::mem {
// The preemption hooks installed now (chm_heap_set_lock_hooks), for the
// test that they lie in allocator_code_range() as the hooks' contract asks.
void heap_lock_hooks(chm_heap_hook_fn* enter, chm_heap_hook_fn* leave);
}  // namespace chm::mem
