// The C library's malloc family, served by the Chimera heap. Linked into a
// program (or into the shared libchimera ahead of libc), these definitions
// interpose on glibc's, so the C library itself, C++ operator new/delete
// (which call malloc, aligned_alloc and free) and every other library in the
// process allocate from the deterministic heap. glibc documents this as
// supported ("Replacing malloc" in its manual) for exactly this set of names.
//
// Kept apart from the rest of the allocator (its own meson variable,
// mem_interpose_sources) because whether a program wants it is the
// linker's decision, not the library's.
//
// Constraints: these run before main (the dynamic loader and static
// constructors allocate), so they rely only on the heap's lazy,
// constructor-free initialisation; and they must never call the C
// library's malloc family themselves.

// No PLT stubs: they would lie in the executable's preemptible code (see
// mem_text.hpp). Calls into the C library go through the GOT instead.
#pragma GCC optimize("no-plt")
#if defined(__aarch64__)
#pragma GCC target("no-outline-atomics")  // atomics inline, not calls into the program's text
#endif

#include <cerrno>
#include <cstdlib>

#include <malloc.h>
#include <unistd.h>

#include "kernel/mem/heap.hpp"
#include "kernel/mem/mem_text.hpp"

namespace {

using chm::mem::heap_allocate;
using chm::mem::heap_allocate_aligned;

CHM_MEM_TEXT inline bool power_of_two(size_t x) { return x != 0 && (x & (x - 1)) == 0; }

CHM_MEM_TEXT inline size_t page_size() { return static_cast<size_t>(sysconf(_SC_PAGESIZE)); }

CHM_MEM_TEXT inline void* or_enomem(void* p) {
    if (!p)
        errno = ENOMEM;
    return p;
}

}  // namespace

extern "C" {

CHM_MEM_TEXT void* malloc(size_t size) noexcept { return or_enomem(heap_allocate(size)); }

CHM_MEM_TEXT void free(void* p) noexcept { chm::mem::heap_free(p); }

CHM_MEM_TEXT void* calloc(size_t n, size_t size) noexcept {
    return or_enomem(chm::mem::heap_allocate_zeroed(n, size));
}

CHM_MEM_TEXT void* realloc(void* p, size_t size) noexcept {
    // glibc's semantics for size 0: free and return NULL.
    bool bad = false;
    void* q = chm::mem::heap_reallocate(p, size, &bad);
    if (!q && (bad || size != 0))
        errno = bad ? EINVAL : ENOMEM;
    return q;
}

CHM_MEM_TEXT void* reallocarray(void* p, size_t n, size_t size) noexcept {
    size_t bytes = 0;
    if (__builtin_mul_overflow(n, size, &bytes)) {
        errno = ENOMEM;
        return nullptr;
    }
    return realloc(p, bytes);
}

CHM_MEM_TEXT void* memalign(size_t align, size_t size) noexcept {
    // glibc rounds a non-power-of-two alignment up rather than failing.
    if (align > (SIZE_MAX >> 1) + 1) {
        errno = EINVAL;
        return nullptr;
    }
    if (!power_of_two(align))
        align = align <= 1 ? 1 : size_t{1} << (sizeof(size_t) * 8 - __builtin_clzl(align));
    return or_enomem(heap_allocate_aligned(align, size));
}

CHM_MEM_TEXT int posix_memalign(void** out, size_t align, size_t size) noexcept {
    if (!power_of_two(align) || align % sizeof(void*) != 0)
        return EINVAL;
    void* p = heap_allocate_aligned(align, size);
    if (!p)
        return ENOMEM;
    *out = p;
    return 0;
}

CHM_MEM_TEXT void* aligned_alloc(size_t align, size_t size) noexcept {
    if (!power_of_two(align)) {
        errno = EINVAL;
        return nullptr;
    }
    return or_enomem(heap_allocate_aligned(align, size));
}

CHM_MEM_TEXT void* valloc(size_t size) noexcept {
    return or_enomem(heap_allocate_aligned(page_size(), size));
}

CHM_MEM_TEXT void* pvalloc(size_t size) noexcept {
    const size_t page = page_size();
    if (size > SIZE_MAX - page) {
        errno = ENOMEM;
        return nullptr;
    }
    size = size == 0 ? page : (size + page - 1) & ~(page - 1);
    return or_enomem(heap_allocate_aligned(page, size));
}

CHM_MEM_TEXT size_t malloc_usable_size(void* p) noexcept { return chm::mem::heap_usable_size(p); }

}  // extern "C"
