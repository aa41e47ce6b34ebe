// The kernel's deterministic memory allocator: a two-level segregated fit
// (TLSF) allocator over memory pools handed to it. It owns block layout,
// the segregated free lists and their bitmaps, and the consistency check.
//
// Why TLSF. A real-time task may allocate on its control path, so the cost
// of malloc and free must have a bound that depends on nothing the task
// cannot see: not on how large the heap is, how many blocks are live or how
// fragmented it has become. TLSF (Masmano, Ripoll, Crespo, Real, 2004) gives
// that bound with plain data structures: free blocks sit in one of
// kFlCount x kSlCount lists, the first level indexing the power of two of the
// size and the second level splitting each power of two into kSlCount equal
// ranges. Two bitmaps say which lists are non-empty, so finding a list whose
// every block is large enough is two find-first-set instructions, and taking
// its head, splitting off the rest, and merging a freed block with its
// physical neighbours (found through boundary tags) are constant work.
// Nothing in allocate/free/reallocate loops over blocks: the bound is a
// constant number of bitmap and list steps, which last_op_steps() exposes so
// a test can assert it (tests/kernel/mem/test_mem_tlsf_bounds.cpp).
// The price is "good fit" instead of best fit: a request is rounded up to the
// next list boundary (at most 1/kSlCount, about 3 %, of its size) so that any
// block of the chosen list fits without searching the list.
//
// Bounds. Counted in bitmap lookups and list/split/merge steps: allocate
// <= 7, allocate_aligned <= 9, free <= 5, reallocate <= 12 (plus the copy
// when the block moves), whatever the heap. Space: every block is
// kAlign-aligned (16 bytes on 64-bit hosts, 8 on the 32-bit m68k) and
// carries a two-word header (16 / 8 bytes); a free block also holds its two
// list links, so the smallest block is kMinBlock (32 / 16 bytes). Rounding
// wastes under 1/32 of a request. Requests up to kMaxRequest (512 GiB /
// 1 GiB) are served; a pool is at most kMaxPool (1 TiB / 2 GiB). The
// bitmaps are 32-bit words and nothing here is atomic, so the m68k needs
// no 64-bit operations.
//
// Chunked commit. The allocator never asks the system for memory: the
// process heap (heap.hpp) reserves a large virtual range once and commits it
// in chunks, appending each to the pool before it. add_pool() recognises a
// region that starts where an existing pool ends and grows that pool instead
// of starting a new one, so the free tail of the old pool and the new chunk
// become one block. Only the rare call that commits a chunk pays a system
// call and page faults; every other allocation is the bounded TLSF path.
//
// Not thread-safe: the heap serialises access with its own lock.
#pragma once

#include <cstddef>
#include <cstdint>

#include "kernel/mem/mem_text.hpp"

namespace chm::mem {

// What check() found wrong, if anything.
struct CheckReport {
    const char* what = nullptr;   // a static description of the first problem
    const void* where = nullptr;  // the block or list head at fault
};

struct TlsfStats {
    std::size_t pool_bytes = 0;      // all bytes handed to add_pool (after alignment)
    std::size_t used_bytes = 0;      // usable bytes of allocated blocks
    std::size_t free_bytes = 0;      // usable bytes of free blocks
    std::size_t overhead_bytes = 0;  // headers, pool descriptors, sentinels
    std::size_t largest_free = 0;    // usable bytes of the largest free block
    std::size_t used_blocks = 0;
    std::size_t free_blocks = 0;
    std::size_t pools = 0;
    std::size_t invalid_frees = 0;   // free/realloc calls rejected by the header check
};

class Tlsf {
public:
    // ------------------------------------------------------------ geometry
    static constexpr std::size_t kAlign = sizeof(void*) >= 8 ? 16 : 8;
    static constexpr unsigned kAlignLog2 = kAlign == 16 ? 4 : 3;
    static constexpr unsigned kSlLog2 = 5;  // 32 second-level lists per power of two
    static constexpr unsigned kSlCount = 1u << kSlLog2;
    // Below kSmallBlock the lists are linear, one per kAlign step.
    static constexpr unsigned kFlShift = kSlLog2 + kAlignLog2;
    static constexpr std::size_t kSmallBlock = std::size_t{1} << kFlShift;
    // Blocks are smaller than 2^kFlMaxLog2: 1 TiB on 64-bit, 2 GiB on 32-bit,
    // chosen so that the first-level bitmap fits one 32-bit word.
    static constexpr unsigned kFlMaxLog2 = sizeof(void*) >= 8 ? 40 : 31;
    static constexpr unsigned kFlCount = kFlMaxLog2 - kFlShift + 1;
    static_assert(kFlCount <= 32, "first-level bitmap is one 32-bit word");

    static constexpr std::size_t kHeader = 2 * sizeof(std::size_t);
    static constexpr std::size_t kMinBlock =
        (kHeader + 2 * sizeof(void*) + kAlign - 1) & ~(kAlign - 1);
    static_assert(kHeader % kAlign == 0, "payloads inherit the header's alignment");
    static constexpr std::size_t kMaxRequest = std::size_t{1} << (kFlMaxLog2 - 1);
    static constexpr std::size_t kMaxPool = (std::size_t{1} << kFlMaxLog2) - kAlign;

    constexpr Tlsf() = default;
    Tlsf(const Tlsf&) = delete;
    Tlsf& operator=(const Tlsf&) = delete;

    // Hand [mem, mem + bytes) to the allocator. The range is trimmed to
    // kAlign. If it begins exactly where an existing pool ends (and the
    // result stays within kMaxPool) that pool grows; otherwise a new pool is
    // made, using at most kMaxPool bytes of the range. Returns false if the
    // range is too small (kMinPool for a new pool, kMinBlock to grow one) or
    // overlaps a pool. O(number of pools).
    bool add_pool(void* mem, std::size_t bytes);
    // A new pool spends one descriptor and one end sentinel (kHeader each).
    static constexpr std::size_t kPoolOverhead = 2 * kHeader;
    static constexpr std::size_t kMinPool = kPoolOverhead + kMinBlock + kAlign;

    // kAlign-aligned block of at least `size` usable bytes (size 0 gives a
    // unique minimal block), or nullptr when no free block is large enough.
    [[nodiscard]] void* allocate(std::size_t size);
    // As allocate, aligned to `align` (a power of two; nullptr otherwise).
    [[nodiscard]] void* allocate_aligned(std::size_t align, std::size_t size);
    // Release p (nullptr is a no-op). A pointer whose header and boundary tag
    // do not describe an allocated block (a double free, a wild pointer in
    // most cases) is refused: false, nothing changes, invalid_frees counts it.
    bool free(void* p);
    // Resize in place when possible (shrinking always is; growing is when the
    // next block is free and large enough), otherwise allocate, copy, free.
    // p == nullptr allocates; size == 0 frees and returns nullptr. On failure
    // returns nullptr and p is untouched.
    [[nodiscard]] void* reallocate(void* p, std::size_t size);
    // Usable bytes of an allocated block (>= what was asked for).
    static std::size_t usable_size(const void* p);
    // Do p's header and boundary tag describe an allocated block? O(1), the
    // test free() applies; p must point into a pool's memory.
    CHM_MEM_INLINE bool is_allocated(const void* p) const { return checked_header(p) != nullptr; }

    TlsfStats stats() const;  // O(1) except largest_free: O(one list)
    // Full walk: every header, boundary tag and list; see tlsf_check.cpp.
    bool check(CheckReport* report = nullptr) const;

    // Bitmap and list steps taken by the last allocate/allocate_aligned/
    // free/reallocate (copying in reallocate is not a step). Evidence for the
    // O(1) bound; costs one increment per step.
    CHM_MEM_INLINE unsigned last_op_steps() const { return steps_; }
    // Does p lie inside a pool? O(number of pools).
    bool contains(const void* p) const;

    // Size-class mapping, public so tests can reason about it.
    struct Index {
        unsigned fl;
        unsigned sl;
    };
    static Index mapping(std::size_t block_size);

    // Block and pool layout, defined in tlsf_block.hpp (named here so that
    // the layout's static checks and white-box tests can see it).
    struct Block;
    struct Pool;

private:

    Block* find_suitable(std::size_t block_size, Index& where);
    void insert_free(Block* b);
    void remove_free(Block* b, Index idx);
    void remove_free(Block* b);
    Block* take_front(Block* b, std::size_t gap);
    void trim_tail(Block* b, std::size_t block_size);
    void release(Block* b);
    void* use_block(Block* b, std::size_t block_size);
    Block* checked_header(const void* p) const;
    bool check_pools(CheckReport* r, std::size_t& free_seen) const;
    bool check_lists(CheckReport* r, std::size_t free_seen) const;
    bool plausible_block(const void* p) const;
    CHM_MEM_INLINE void step() { ++steps_; }

    std::uint32_t fl_map_ = 0;
    std::uint32_t sl_map_[kFlCount] = {};
    Block* heads_[kFlCount][kSlCount] = {};
    Pool* pools_ = nullptr;
    std::size_t pool_count_ = 0;
    std::size_t pool_bytes_ = 0;
    std::size_t used_block_bytes_ = 0;  // whole blocks, headers included
    std::size_t free_block_bytes_ = 0;
    std::size_t used_blocks_ = 0;
    std::size_t free_blocks_ = 0;
    std::size_t invalid_frees_ = 0;
    unsigned steps_ = 0;
};

}  // namespace chm::mem
