// TLSF operations: pools, size classes, allocate/free/reallocate. The layout
// is in tlsf_block.hpp, the consistency walk in tlsf_check.cpp, the design
// and its bounds at the top of tlsf.hpp.

// No PLT stubs: they would lie in the executable's preemptible code (see
// mem_text.hpp). Calls into the C library go through the GOT instead.
#pragma GCC optimize("no-plt")
#if defined(__aarch64__)
#pragma GCC target("no-outline-atomics")  // atomics inline, not calls into the program's text
#endif

#include "kernel/mem/tlsf.hpp"

#include <cstring>

#include "kernel/mem/tlsf_block.hpp"
#include "kernel/mem/mem_text.hpp"

namespace chm::mem {

namespace {

// Index of the highest set bit; x != 0. One instruction on every target
// (bsr/clz; bfffo on the 68020+).
CHM_MEM_TEXT inline unsigned fls(std::size_t x) {
    if constexpr (sizeof(std::size_t) == sizeof(unsigned long long))
        return 63u - static_cast<unsigned>(__builtin_clzll(x));
    else
        return 31u - static_cast<unsigned>(__builtin_clz(x));
}

CHM_MEM_TEXT inline unsigned ffs32(std::uint32_t x) { return static_cast<unsigned>(__builtin_ctz(x)); }

CHM_MEM_TEXT inline std::uintptr_t align_up(std::uintptr_t v, std::size_t a) {
    return (v + (a - 1)) & ~static_cast<std::uintptr_t>(a - 1);
}

// Whole-block size that serves a request of `size` usable bytes.
CHM_MEM_TEXT inline std::size_t block_size_for(std::size_t size) {
    const std::size_t s = align_up(size + Tlsf::kHeader, Tlsf::kAlign);
    return s < Tlsf::kMinBlock ? Tlsf::kMinBlock : s;
}

}  // namespace

CHM_MEM_TEXT Tlsf::Index Tlsf::mapping(std::size_t s) {
    if (s < kSmallBlock)
        return {0, static_cast<unsigned>(s >> kAlignLog2)};
    const unsigned f = fls(s);
    const auto sl = static_cast<unsigned>(s >> (f - kSlLog2)) ^ kSlCount;
    return {f - kFlShift + 1, sl};
}

// ------------------------------------------------------------ free lists

CHM_MEM_TEXT void Tlsf::insert_free(Block* b) {
    step();
    const Index i = mapping(b->size());
    Block* head = heads_[i.fl][i.sl];
    b->link_next = head;
    b->link_prev = nullptr;
    if (head)
        head->link_prev = b;
    heads_[i.fl][i.sl] = b;
    sl_map_[i.fl] |= 1u << i.sl;
    fl_map_ |= 1u << i.fl;
    ++free_blocks_;
    free_block_bytes_ += b->size();
}

CHM_MEM_TEXT void Tlsf::remove_free(Block* b, Index i) {
    step();
    Block* next = b->link_next;
    Block* prev = b->link_prev;
    if (next)
        next->link_prev = prev;
    if (prev) {
        prev->link_next = next;
    } else {
        heads_[i.fl][i.sl] = next;
        if (!next) {
            sl_map_[i.fl] &= ~(1u << i.sl);
            if (!sl_map_[i.fl])
                fl_map_ &= ~(1u << i.fl);
        }
    }
    --free_blocks_;
    free_block_bytes_ -= b->size();
}

CHM_MEM_TEXT void Tlsf::remove_free(Block* b) { remove_free(b, mapping(b->size())); }

// Head of a list whose every block is at least `size` bytes: round the size
// up to the next list boundary, then two find-first-set operations.
CHM_MEM_TEXT Tlsf::Block* Tlsf::find_suitable(std::size_t size, Index& where) {
    step();
    if (size >= kSmallBlock)
        size += (std::size_t{1} << (fls(size) - kSlLog2)) - 1;
    Index i = mapping(size);
    if (i.fl >= kFlCount)
        return nullptr;
    std::uint32_t sl_bits = sl_map_[i.fl] & (~0u << i.sl);
    if (!sl_bits) {
        step();
        const std::uint32_t fl_bits = i.fl + 1 < 32 ? fl_map_ & (~0u << (i.fl + 1)) : 0;
        if (!fl_bits)
            return nullptr;
        i.fl = ffs32(fl_bits);
        sl_bits = sl_map_[i.fl];
    }
    i.sl = ffs32(sl_bits);
    where = i;
    return heads_[i.fl][i.sl];
}

// ------------------------------------------------------ block surgery

// b is on no list and its neighbours' tags describe it. Merge it with free
// physical neighbours (at most one on each side: free blocks never touch)
// and put the result on its list.
CHM_MEM_TEXT void Tlsf::release(Block* b) {
    if (b->prev_is_free()) {
        step();
        Block* p = b->prev();
        remove_free(p);
        p->set_size(p->size() + b->size());
        b = p;
    }
    Block* n = b->next();
    if (n->is_free()) {
        step();
        remove_free(n);
        b->set_size(b->size() + n->size());
        n = b->next();
    }
    b->set_free(true);
    n->prev_size = b->size();
    n->set_prev_free(true);
    insert_free(b);
}

// Cut b (allocated, or free and on no list) down to `keep` bytes when the
// rest can form a block of its own, and release the rest.
CHM_MEM_TEXT void Tlsf::trim_tail(Block* b, std::size_t keep) {
    const std::size_t size = b->size();
    if (size - keep < kMinBlock)
        return;
    step();
    b->set_size(keep);
    Block* rest = b->next();
    rest->prev_size = keep;
    rest->size_flags = size - keep;  // not free yet; b before it is in use
    rest->next()->prev_size = size - keep;
    release(rest);
}

// b is free and on no list, b's predecessor is in use. Split off its first
// `gap` bytes as a free block of their own and return the block after them.
CHM_MEM_TEXT Tlsf::Block* Tlsf::take_front(Block* b, std::size_t gap) {
    step();
    Block* a = Block::at(b, gap);
    a->prev_size = gap;
    a->size_flags = (b->size() - gap) | Block::kPrevFree;
    a->next()->prev_size = a->size();
    b->set_size(gap);
    insert_free(b);  // stays flagged free; its neighbours are in use
    return a;
}

// Mark b (free, on no list, at least `size` bytes) allocated, returning any
// excess to the free lists.
CHM_MEM_TEXT void* Tlsf::use_block(Block* b, std::size_t size) {
    b->set_free(false);
    b->next()->set_prev_free(false);
    trim_tail(b, size);
    ++used_blocks_;
    used_block_bytes_ += b->size();
    return b->payload();
}

// The header of an allocated block at p, or nullptr when p cannot be one:
// cheap O(1) tests of alignment, flags and the successor's boundary tag that
// catch double frees and most wild pointers before they corrupt the lists.
CHM_MEM_TEXT Tlsf::Block* Tlsf::checked_header(const void* p) const {
    if (reinterpret_cast<std::uintptr_t>(p) & (kAlign - 1))
        return nullptr;
    Block* b = Block::from_payload(p);
    const std::size_t size = b->size();
    if (b->is_free() || size < kMinBlock || (size & (kAlign - 1)) || size > kMaxPool)
        return nullptr;
    const Block* n = b->next();
    if (n->prev_size != size || n->prev_is_free())
        return nullptr;
    return b;
}

// ------------------------------------------------------------- the API

CHM_MEM_TEXT void* Tlsf::allocate(std::size_t size) {
    steps_ = 0;
    if (size > kMaxRequest)
        return nullptr;
    const std::size_t need = block_size_for(size);
    Index i{};
    Block* b = find_suitable(need, i);
    if (!b)
        return nullptr;
    remove_free(b, i);
    return use_block(b, need);
}

CHM_MEM_TEXT void* Tlsf::allocate_aligned(std::size_t align, std::size_t size) {
    if (align <= kAlign && align != 0 && (align & (align - 1)) == 0)
        return allocate(size);
    steps_ = 0;
    if (align == 0 || (align & (align - 1)) || size > kMaxRequest || align > kMaxRequest)
        return nullptr;
    const std::size_t need = block_size_for(size);
    // The payload may need to move forward by up to align - kAlign bytes; a
    // non-zero gap must hold a free block of its own, hence the extra
    // kMinBlock. Any block of this size can be carved without a search.
    Index i{};
    Block* b = find_suitable(need + align + kMinBlock - kAlign, i);
    if (!b)
        return nullptr;
    remove_free(b, i);
    const std::uintptr_t payload = reinterpret_cast<std::uintptr_t>(b->payload());
    std::uintptr_t target = align_up(payload, align);
    if (target != payload && target - payload < kMinBlock)
        target = align_up(payload + kMinBlock, align);
    if (target != payload)
        b = take_front(b, target - payload);
    return use_block(b, need);
}

CHM_MEM_TEXT bool Tlsf::free(void* p) {
    steps_ = 0;
    if (!p)
        return true;
    Block* b = checked_header(p);
    if (!b) {
        ++invalid_frees_;
        return false;
    }
    --used_blocks_;
    used_block_bytes_ -= b->size();
    release(b);
    return true;
}

CHM_MEM_TEXT void* Tlsf::reallocate(void* p, std::size_t size) {
    if (!p)
        return allocate(size);
    if (size == 0) {
        free(p);
        return nullptr;
    }
    steps_ = 0;
    Block* b = checked_header(p);
    if (!b) {
        ++invalid_frees_;
        return nullptr;
    }
    if (size > kMaxRequest)
        return nullptr;
    const std::size_t need = block_size_for(size);
    const std::size_t cur = b->size();
    if (need <= cur) {
        trim_tail(b, need);
        used_block_bytes_ -= cur - b->size();
        return p;
    }
    Block* n = b->next();
    if (n->is_free() && cur + n->size() >= need) {
        // Grow into the free successor: the payload does not move.
        remove_free(n);
        b->set_size(cur + n->size());
        b->next()->prev_size = b->size();
        b->next()->set_prev_free(false);
        trim_tail(b, need);
        used_block_bytes_ += b->size() - cur;
        return p;
    }
    const unsigned steps_so_far = steps_;
    void* q = allocate(size);
    steps_ += steps_so_far;
    if (!q)
        return nullptr;
    std::memcpy(q, p, cur - kHeader);
    --used_blocks_;
    used_block_bytes_ -= cur;
    release(b);
    return q;
}

CHM_MEM_TEXT std::size_t Tlsf::usable_size(const void* p) {
    return p ? Block::from_payload(p)->size() - kHeader : 0;
}

// --------------------------------------------------------------- pools

CHM_MEM_TEXT bool Tlsf::add_pool(void* mem, std::size_t bytes) {
    const auto start = reinterpret_cast<std::uintptr_t>(mem);
    if (start + bytes < start)
        return false;
    const std::uintptr_t lo = align_up(start, kAlign);
    const std::uintptr_t hi = (start + bytes) & ~static_cast<std::uintptr_t>(kAlign - 1);
    if (hi <= lo)
        return false;
    std::size_t len = hi - lo;

    Pool* grow = nullptr;
    for (Pool* p = pools_; p; p = p->next) {
        if (lo < p->hi() && p->lo() < hi)
            return false;
        if (p->hi() == lo && len >= kMinBlock && len <= kMaxPool - p->bytes)
            grow = p;
    }
    if (grow) {
        // The old sentinel becomes the header of a block spanning the new
        // range; a new sentinel closes the pool; release() merges the block
        // with a free tail of the old pool.
        Block* b = grow->sentinel();
        b->size_flags = len | (b->size_flags & Block::kPrevFree);
        grow->bytes += len;
        Block* s = grow->sentinel();
        s->prev_size = len;
        s->size_flags = 0;
        pool_bytes_ += len;
        release(b);
        return true;
    }
    if (len < kMinPool)
        return false;
    if (len > kMaxPool)
        len = kMaxPool;
    Pool* p = reinterpret_cast<Pool*>(lo);
    p->next = pools_;
    p->bytes = len;
    pools_ = p;
    ++pool_count_;
    pool_bytes_ += len;
    Block* b = p->first();
    b->prev_size = 0;
    b->size_flags = len - kPoolOverhead;
    Block* s = p->sentinel();
    s->prev_size = b->size();
    s->size_flags = 0;
    release(b);
    return true;
}

CHM_MEM_TEXT bool Tlsf::contains(const void* ptr) const {
    const auto a = reinterpret_cast<std::uintptr_t>(ptr);
    for (const Pool* p = pools_; p; p = p->next)
        if (a >= p->lo() && a < p->hi())
            return true;
    return false;
}

CHM_MEM_TEXT TlsfStats Tlsf::stats() const {
    TlsfStats s;
    s.pool_bytes = pool_bytes_;
    s.used_bytes = used_block_bytes_ - used_blocks_ * kHeader;
    s.free_bytes = free_block_bytes_ - free_blocks_ * kHeader;
    s.overhead_bytes = pool_bytes_ - s.used_bytes - s.free_bytes;
    s.used_blocks = used_blocks_;
    s.free_blocks = free_blocks_;
    s.pools = pool_count_;
    s.invalid_frees = invalid_frees_;
    if (fl_map_) {
        // The largest block is on the highest non-empty list, not
        // necessarily at its head.
        const unsigned fl = 31u - static_cast<unsigned>(__builtin_clz(fl_map_));
        const unsigned sl = 31u - static_cast<unsigned>(__builtin_clz(sl_map_[fl]));
        for (const Block* b = heads_[fl][sl]; b; b = b->link_next)
            if (b->size() - kHeader > s.largest_free)
                s.largest_free = b->size() - kHeader;
    }
    return s;
}

}  // namespace chm::mem
