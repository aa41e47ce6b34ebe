// The TLSF consistency walk. check() trusts nothing it has not verified: it
// walks every pool block by block (headers, boundary tags, flags, no two free
// neighbours, sizes adding up to the pool), then every free list (bitmaps,
// links, size classes), and compares both with the allocator's counters.
// Pointers read from the heap are range-checked before they are followed,
// so a corrupted heap yields a report rather than a crash, and every walk is
// bounded by a count so a cycle cannot hang it. Cost: O(blocks + lists).

// No PLT stubs: they would lie in the executable's preemptible code (see
// mem_text.hpp). Calls into the C library go through the GOT instead.
#pragma GCC optimize("no-plt")
#if defined(__aarch64__)
#pragma GCC target("no-outline-atomics")  // atomics inline, not calls into the program's text
#endif

#include "kernel/mem/tlsf.hpp"

#include "kernel/mem/tlsf_block.hpp"
#include "kernel/mem/mem_text.hpp"

namespace chm::mem {

namespace {

CHM_MEM_TEXT bool fail(CheckReport* r, const char* what, const void* where) {
    if (r) {
        r->what = what;
        r->where = where;
    }
    return false;
}

}  // namespace

// Could p be the header of a block of some pool?
CHM_MEM_TEXT bool Tlsf::plausible_block(const void* p) const {
    const auto a = reinterpret_cast<std::uintptr_t>(p);
    if (a & (kAlign - 1))
        return false;
    std::size_t n = 0;
    for (const Pool* pool = pools_; pool && n < pool_count_; pool = pool->next, ++n) {
        const auto first = reinterpret_cast<std::uintptr_t>(pool->first());
        const auto sentinel = reinterpret_cast<std::uintptr_t>(pool->sentinel());
        if (a >= first && a < sentinel)
            return true;
    }
    return false;
}

CHM_MEM_TEXT bool Tlsf::check_pools(CheckReport* r, std::size_t& free_seen) const {
    std::size_t pools = 0, total = 0;
    std::size_t used_n = 0, used_b = 0, free_n = 0, free_b = 0;
    for (const Pool* p = pools_; p; p = p->next) {
        if (++pools > pool_count_)
            return fail(r, "pool list longer than the pool count (cycle?)", p);
        if ((p->lo() & (kAlign - 1)) || p->bytes < kMinPool || (p->bytes & (kAlign - 1)) ||
            p->bytes > kMaxPool)
            return fail(r, "pool descriptor corrupt", p);
        total += p->bytes;
        const Block* const end = p->sentinel();
        const Block* b = p->first();
        std::size_t prev_size = 0;
        bool prev_free = false;
        while (b != end) {
            const std::size_t size = b->size();
            if (size < kMinBlock || (size & (kAlign - 1)))
                return fail(r, "block size invalid (header overwritten)", b);
            const auto room = reinterpret_cast<std::uintptr_t>(end) -
                              reinterpret_cast<std::uintptr_t>(b);
            if (size > room)
                return fail(r, "block runs past the end of its pool", b);
            if (b->prev_size != prev_size)
                return fail(r, "boundary tag: prev_size differs from the previous block", b);
            if (b->prev_is_free() != prev_free)
                return fail(r, "prev-free flag differs from the previous block", b);
            if (b->is_free()) {
                if (prev_free)
                    return fail(r, "two adjacent free blocks", b);
                const Block* lp = b->link_prev;
                const Block* ln = b->link_next;
                if (!lp) {
                    const Index i = mapping(size);
                    if (i.fl >= kFlCount || heads_[i.fl][i.sl] != b)
                        return fail(r, "free block is neither on a list nor its head", b);
                } else if (!plausible_block(lp) || lp->link_next != b) {
                    return fail(r, "free block's list predecessor does not link to it", b);
                }
                if (ln && (!plausible_block(ln) || ln->link_prev != b))
                    return fail(r, "free block's list successor does not link back", b);
                ++free_n;
                free_b += size;
            } else {
                ++used_n;
                used_b += size;
            }
            prev_size = size;
            prev_free = b->is_free();
            b = b->next();
        }
        if (end->size() != 0 || end->is_free())
            return fail(r, "pool end sentinel overwritten", end);
        if (end->prev_size != prev_size || end->prev_is_free() != prev_free)
            return fail(r, "boundary tag at the pool end differs from the last block", end);
    }
    if (pools != pool_count_)
        return fail(r, "pool list shorter than the pool count", pools_);
    if (total != pool_bytes_)
        return fail(r, "pool sizes do not add up to the bytes handed in", pools_);
    if (used_n != used_blocks_ || used_b != used_block_bytes_)
        return fail(r, "allocated-block counters disagree with the heap walk", nullptr);
    if (free_n != free_blocks_ || free_b != free_block_bytes_)
        return fail(r, "free-block counters disagree with the heap walk", nullptr);
    free_seen = free_n;
    return true;
}

CHM_MEM_TEXT bool Tlsf::check_lists(CheckReport* r, std::size_t free_seen) const {
    if (kFlCount < 32 && (fl_map_ >> (kFlCount % 32)) != 0)
        return fail(r, "first-level bitmap has bits beyond the last class", nullptr);
    std::size_t listed = 0;
    for (unsigned fl = 0; fl < kFlCount; ++fl) {
        if (((fl_map_ >> fl) & 1u) != (sl_map_[fl] != 0 ? 1u : 0u))
            return fail(r, "first-level bitmap disagrees with the second level", &sl_map_[fl]);
        for (unsigned sl = 0; sl < kSlCount; ++sl) {
            const Block* head = heads_[fl][sl];
            if (((sl_map_[fl] >> sl) & 1u) != (head ? 1u : 0u))
                return fail(r, "second-level bitmap disagrees with its free list", head);
            const Block* prev = nullptr;
            for (const Block* b = head; b; prev = b, b = b->link_next) {
                if (!plausible_block(b))
                    return fail(r, "free list points outside every pool", b);
                if (++listed > free_seen)
                    return fail(r, "free lists hold more blocks than the heap (cycle?)", b);
                if (!b->is_free())
                    return fail(r, "allocated block on a free list", b);
                if (b->link_prev != prev)
                    return fail(r, "free list back link broken", b);
                const Index i = mapping(b->size());
                if (i.fl != fl || i.sl != sl)
                    return fail(r, "free block on the wrong list for its size", b);
            }
        }
    }
    if (listed != free_seen)
        return fail(r, "free blocks missing from the free lists", nullptr);
    return true;
}

CHM_MEM_TEXT bool Tlsf::check(CheckReport* report) const {
    std::size_t free_seen = 0;
    return check_pools(report, free_seen) && check_lists(report, free_seen);
}

}  // namespace chm::mem
