// The public C API of include/chimera/mem.h: errno and argument handling
// over the process heap (heap.hpp).

// No PLT stubs: they would lie in the executable's preemptible code (see
// mem_text.hpp). Calls into the C library go through the GOT instead.
#pragma GCC optimize("no-plt")
#if defined(__aarch64__)
#pragma GCC target("no-outline-atomics")  // atomics inline, not calls into the program's text
#endif

#include "chimera/mem.h"

#include <cerrno>

#include "kernel/mem/heap.hpp"
#include "kernel/mem/mem_text.hpp"

using namespace chm::mem;

extern "C" {

CHM_MEM_TEXT void* chm_malloc(size_t size) {
    void* p = heap_allocate(size);
    if (!p)
        errno = ENOMEM;
    return p;
}

CHM_MEM_TEXT void* chm_calloc(size_t n, size_t size) {
    void* p = heap_allocate_zeroed(n, size);
    if (!p)
        errno = ENOMEM;
    return p;
}

CHM_MEM_TEXT void* chm_realloc(void* p, size_t size) {
    bool bad = false;
    void* q = heap_reallocate(p, size, &bad);
    if (!q && bad)
        errno = EINVAL;
    else if (!q && size != 0)
        errno = ENOMEM;
    return q;
}

CHM_MEM_TEXT void chm_free(void* p) { heap_free(p); }

CHM_MEM_TEXT void* chm_memalign(size_t align, size_t size) {
    if (align == 0 || (align & (align - 1))) {
        errno = EINVAL;
        return nullptr;
    }
    void* p = heap_allocate_aligned(align, size);
    if (!p)
        errno = ENOMEM;
    return p;
}

CHM_MEM_TEXT size_t chm_malloc_usable_size(void* p) { return heap_usable_size(p); }

CHM_MEM_TEXT int chm_mem_check(void) { return heap_check() ? 0 : -EFAULT; }

CHM_MEM_TEXT int chm_mem_stats(struct chm_mem_stats* out) {
    if (!out)
        return -EINVAL;
    const HeapStats s = heap_stats();
    out->reserved_bytes = s.reserved_bytes;
    out->committed_bytes = s.committed_bytes;
    out->used_bytes = s.tlsf.used_bytes;
    out->free_bytes = s.tlsf.free_bytes;
    out->overhead_bytes = s.tlsf.overhead_bytes;
    out->largest_free = s.tlsf.largest_free;
    out->used_blocks = s.tlsf.used_blocks;
    out->free_blocks = s.tlsf.free_blocks;
    out->commits = s.commits;
    out->invalid_frees = s.tlsf.invalid_frees + s.foreign_frees;
    return 0;
}

}  // extern "C"
