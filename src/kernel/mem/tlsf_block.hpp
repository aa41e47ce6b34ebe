// Block and pool layout of the TLSF allocator, shared by tlsf.cpp (the
// operations) and tlsf_check.cpp (the consistency walk). Private to them.
//
//   pool:  [Pool descriptor][block][block]...[block][sentinel header]
//   block: [prev_size][size | flags][payload ...................]
//   free:  [prev_size][size | flags][link_next][link_prev][......]
//
// prev_size is the boundary tag: the size of the physical predecessor, kept
// valid for every block (0 for a pool's first block), so free() finds the
// block before it in one step and check() can verify every tag. The sentinel
// is a header of size 0 that is never free; it stops merging at a pool's end
// and becomes an ordinary block when the pool grows.
#pragma once

#include "kernel/mem/mem_text.hpp"
#include "kernel/mem/tlsf.hpp"

namespace chm::mem {

struct Tlsf::Block {
    static constexpr std::size_t kFree = 1;
    static constexpr std::size_t kPrevFree = 2;
    static constexpr std::size_t kFlags = kFree | kPrevFree;

    std::size_t prev_size;
    std::size_t size_flags;
    // Free blocks only; they overlay the first bytes of the payload.
    Block* link_next;
    Block* link_prev;

    CHM_MEM_INLINE std::size_t size() const { return size_flags & ~kFlags; }
    CHM_MEM_INLINE bool is_free() const { return (size_flags & kFree) != 0; }
    CHM_MEM_INLINE bool prev_is_free() const { return (size_flags & kPrevFree) != 0; }
    CHM_MEM_INLINE void set_size(std::size_t s) { size_flags = s | (size_flags & kFlags); }
    CHM_MEM_INLINE void set_free(bool f) { size_flags = f ? (size_flags | kFree) : (size_flags & ~kFree); }
    CHM_MEM_INLINE void set_prev_free(bool f) {
        size_flags = f ? (size_flags | kPrevFree) : (size_flags & ~kPrevFree);
    }

    CHM_MEM_INLINE Block* next() const { return at(this, size()); }
    CHM_MEM_INLINE Block* prev() const { return at(this, 0 - prev_size); }
    CHM_MEM_INLINE void* payload() { return reinterpret_cast<char*>(this) + kHeader; }

    CHM_MEM_INLINE static Block* at(const void* base, std::size_t offset) {
        // Offsets wrap on purpose for prev(): unsigned arithmetic is exact.
        return reinterpret_cast<Block*>(
            reinterpret_cast<std::uintptr_t>(base) + offset);
    }
    CHM_MEM_INLINE static Block* from_payload(const void* p) { return at(p, 0 - kHeader); }
};

struct Tlsf::Pool {
    Pool* next;
    std::size_t bytes;  // from this descriptor to the end of the sentinel

    CHM_MEM_INLINE Block* first() const { return Block::at(this, sizeof(Pool)); }
    CHM_MEM_INLINE Block* sentinel() const { return Block::at(this, bytes - kHeader); }
    CHM_MEM_INLINE std::uintptr_t lo() const { return reinterpret_cast<std::uintptr_t>(this); }
    CHM_MEM_INLINE std::uintptr_t hi() const { return lo() + bytes; }
};

static_assert(sizeof(Tlsf::Block) <= Tlsf::kMinBlock);
static_assert(sizeof(Tlsf::Pool) == Tlsf::kHeader, "the descriptor keeps blocks aligned");

}  // namespace chm::mem
