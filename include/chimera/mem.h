/*
 * Chimera memory allocation: the malloc family over the RTPU's heap.
 *
 * The heap is a TLSF (two-level segregated fit) allocator: chm_malloc,
 * chm_free and the rest take a bounded, constant number of steps whatever
 * the heap's size or fragmentation. The heap reserves CHIMERA_HEAP_MB
 * megabytes of address space (default 1024) and makes it usable in 4 MiB
 * chunks as it fills; only the call that makes a new chunk usable pays for
 * it (a system call and page faults). Every function is thread-safe and may
 * be called from any task or thread, but not from a signal handler.
 *
 * Blocks are aligned to 16 bytes on 64-bit targets and 8 bytes on m68k.
 *
 * Errors follow UNIX: pointer-returning functions return NULL and set errno;
 * int-returning functions return 0 or a negative errno value.
 */
#ifndef CHIMERA_MEM_H
#define CHIMERA_MEM_H

#include "chimera/status.h"

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* A snapshot of the heap, taken under its lock. */
struct chm_mem_stats {
    size_t reserved_bytes;  /* address space reserved for the heap */
    size_t committed_bytes; /* of which usable so far (whole chunks) */
    size_t used_bytes;      /* usable bytes of allocated blocks */
    size_t free_bytes;      /* usable bytes of free blocks in committed memory */
    size_t overhead_bytes;  /* block headers and bookkeeping in committed memory */
    size_t largest_free;    /* usable bytes of the largest free block; requests
                               up to about 97 % of it are served without
                               committing another chunk */
    size_t used_blocks;     /* allocated blocks */
    size_t free_blocks;     /* free blocks */
    size_t commits;         /* chunks committed so far */
    size_t invalid_frees;   /* chm_free/chm_realloc calls given a pointer that
                               was not an allocated block (ignored) */
};

/* Allocate at least `size` bytes (uninitialised). size 0 returns a unique
 * pointer that may be freed.
 * Errors: NULL with errno ENOMEM when the heap's reservation is exhausted or
 * the system refuses to commit more memory. */
void *chm_malloc(size_t size);

/* Allocate an array of `n` elements of `size` bytes, all zero.
 * Errors: NULL with errno ENOMEM when n * size overflows or as chm_malloc. */
void *chm_calloc(size_t n, size_t size);

/* Resize the block at p to at least `size` bytes, keeping its contents up to
 * the smaller of the two sizes. The block moves only when it cannot grow in
 * place. p NULL behaves as chm_malloc(size); size 0 frees p and returns NULL.
 * Errors: NULL with errno ENOMEM when no block is large enough (p is left
 * valid and unchanged); NULL with errno EINVAL when p is not a block
 * allocated by this heap (nothing is changed, invalid_frees counts it). */
void *chm_realloc(void *p, size_t size);

/* Release the block at p. NULL is a no-op. A pointer that is not an
 * allocated block of this heap (a double free, a foreign pointer) is
 * detected by a header check in most cases and then ignored and counted in
 * invalid_frees. */
void chm_free(void *p);

/* Allocate at least `size` bytes aligned to `align` bytes.
 * Errors: NULL with errno EINVAL when align is not a power of two; NULL
 * with errno ENOMEM as chm_malloc. */
void *chm_memalign(size_t align, size_t size);

/* The usable size of the block at p (at least what was asked for), 0 for NULL
 * or a pointer that is not an allocated block of this heap. */
size_t chm_malloc_usable_size(void *p);

/* Walk the whole heap and verify its consistency: every block's header and
 * boundary tag, the free lists against their bitmaps, no two adjacent free
 * blocks, the block sizes adding up to the committed memory. Takes time
 * proportional to the number of blocks, holding the heap lock.
 * Returns 0 when consistent, -EFAULT when the heap is corrupt. */
CHM_CHECK int chm_mem_check(void);

/* Fill *out with a snapshot of the heap's statistics.
 * Returns 0, or -EINVAL when out is NULL. */
CHM_CHECK int chm_mem_stats(struct chm_mem_stats *out);

#ifdef __cplusplus
}
#endif

#endif /* CHIMERA_MEM_H */
