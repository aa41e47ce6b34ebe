// The offset allocator of every local window and of common memory:
// first fit over a chain of boundary-tagged blocks (layout.hpp), offsets
// only, so it works whatever address each process maps the file at (the
// kernel's TLSF in src/kernel/mem/ stores pointers and cannot).
//
// Crash safety: every change to the chain is one aligned 32-bit store done
// in an order that keeps the chain walkable (a split writes the new tail
// block's header inside the old block before shrinking it; a merge grows
// the surviving block in one store). The free list and the counters can
// always be rebuilt from the chain, so a holder killed anywhere leaves an
// arena arena_rebuild_locked() repairs. Allocation is O(free blocks),
// bounded by the arena's block count; it happens at object creation, never
// on a data path.
#include <cerrno>
#include <cstdio>

#include "ipc/backplane/backplane.hpp"

namespace chm::bp {

namespace {

constexpr auto R = std::memory_order_relaxed;

BlockHeader* block(const View& v, std::uint32_t off) { return v.at<BlockHeader>(off); }
std::uint32_t bsize(const BlockHeader* b) { return b->size_flags.load(R) & ~kUsed; }
bool bused(const BlockHeader* b) { return b->size_flags.load(R) & kUsed; }
A32* next_link(const View& v, std::uint32_t off) { return v.at<A32>(off + sizeof(BlockHeader)); }
A32* prev_link(const View& v, std::uint32_t off) { return v.at<A32>(off + sizeof(BlockHeader) + 4); }
// An arena's bounds come from the process's validated copy of the layout,
// never from the arena header in the file: a header changed there cannot
// send a walk outside the map (a->self + a->size could even wrap).
std::uint32_t bytes_of(const View& v, const ArenaHeader* a) {
    return v.off_of(a) == v.layout.regions[kRegionCommon].offset ? v.geo().common_size : v.geo().local_window_size;
}
std::uint32_t first(const View& v, const ArenaHeader* a) { return v.off_of(a) + std::uint32_t(sizeof(ArenaHeader)); }
std::uint32_t end(const View& v, const ArenaHeader* a) { return v.off_of(a) + bytes_of(v, a); }

void list_push(const View& v, ArenaHeader* a, std::uint32_t off) {
    const std::uint32_t h = a->free_head.load(R);
    next_link(v, off)->store(h, R);
    prev_link(v, off)->store(0, R);
    if (h) prev_link(v, h)->store(off, R);
    a->free_head.store(off, R);
}

void list_unlink(const View& v, ArenaHeader* a, std::uint32_t off) {
    const std::uint32_t n = next_link(v, off)->load(R), p = prev_link(v, off)->load(R);
    if (p) next_link(v, p)->store(n, R); else a->free_head.store(n, R);
    if (n) prev_link(v, n)->store(p, R);
}

void fix_prev_of_next(const View& v, const ArenaHeader* a, std::uint32_t off) {
    const std::uint32_t nx = off + bsize(block(v, off));
    if (nx < end(v, a)) block(v, nx)->prev_size.store(bsize(block(v, off)), R);
}

void write_header(const View& v, std::uint32_t off, std::uint32_t size_flags, std::uint32_t prev) {
    BlockHeader* b = block(v, off);
    b->prev_size.store(prev, R);
    b->owner.store(0, R);
    b->tag.store(off ^ kBlockTagXor, R);
    b->size_flags.store(size_flags, R);
}

}  // namespace

void arena_init(const View& v, std::uint32_t off, std::uint32_t size) {
    ArenaHeader* a = v.at<ArenaHeader>(off);
    a->magic = kArenaMagic;
    a->self = off;
    a->size = size;
    const std::uint32_t b = first(v, a);
    write_header(v, b, size - sizeof(ArenaHeader), 0);
    a->free_head.store(0, R);
    list_push(v, a, b);
    a->used_bytes.store(0, R);
    a->blocks.store(1, R);
    a->broken.store(0, R);
}

int arena_lock(const View& v, ArenaHeader* a, std::uint32_t me) {
    const int r = lock_acquire(v, &a->lock, me, kInternalPollNs, kInternalTimeoutNs);
    if (r == -ETIMEDOUT) return r;
    if (r == -EOWNERDEAD && a->lock.dirty.load(std::memory_order_acquire)) {
        arena_rebuild_locked(v, a);
        lock_clear_dirty(&a->lock);
    }
    if (a->broken.load(R)) {
        lock_release(&a->lock);
        return -ENOTRECOVERABLE;
    }
    char why[200];
    if (arena_validate_locked(v, a, why, sizeof why) != 0) {
        lock_release(&a->lock);
        set_error("backplane: %s", why);
        return kCorrupt;
    }
    return 0;
}

void arena_unlock(ArenaHeader* a) { lock_release(&a->lock); }

std::uint32_t arena_alloc_locked(const View& v, ArenaHeader* a, std::uint32_t size,
                                 std::uint32_t owner) {
    if (size == 0 || size > bytes_of(v, a)) return 0;
    std::uint32_t need = (size + kBlockAlign - 1) / kBlockAlign * kBlockAlign + sizeof(BlockHeader);
    if (need < kMinBlock) need = kMinBlock;
    std::uint32_t b = a->free_head.load(R);
    for (std::uint32_t guard = a->blocks.load(R) + 1; b && guard; --guard) {
        if (bsize(block(v, b)) >= need) break;
        b = next_link(v, b)->load(R);
    }
    if (!b || bsize(block(v, b)) < need) return 0;
    lock_mark_dirty(&a->lock);
    BlockHeader* h = block(v, b);
    const std::uint32_t sz = bsize(h);
    list_unlink(v, a, b);
    h->owner.store(owner, R);
    if (sz - need >= kMinBlock) {
        const std::uint32_t rest = b + need;
        write_header(v, rest, sz - need, need);  // inside b until the next store
        h->size_flags.store(need | kUsed, R);    // the split happens here
        fix_prev_of_next(v, a, rest);
        list_push(v, a, rest);
        a->blocks.fetch_add(1, R);
    } else {
        h->size_flags.store(sz | kUsed, R);
    }
    a->used_bytes.fetch_add(bsize(h), R);
    lock_clear_dirty(&a->lock);
    return b + sizeof(BlockHeader);
}

void arena_commit(const View& v, std::uint32_t payload) {
    block(v, payload - sizeof(BlockHeader))->owner.store(0, std::memory_order_release);
}

bool arena_block_used(const View& v, const ArenaHeader* a, std::uint32_t payload, std::uint32_t size) {
    if (payload < first(v, a) + sizeof(BlockHeader) || payload >= end(v, a) || payload % kBlockAlign) return false;
    const std::uint32_t b = payload - sizeof(BlockHeader);
    const BlockHeader* h = block(v, b);
    // 64-bit: a size near 4 GiB must not wrap to a small requirement.
    return bused(h) && h->tag.load(R) == (b ^ kBlockTagXor) && bsize(h) >= std::uint64_t(size) + sizeof(BlockHeader) &&
           bsize(h) <= end(v, a) - b;
}

int arena_free_locked(const View& v, ArenaHeader* a, std::uint32_t payload) {
    if (!arena_block_used(v, a, payload, 0)) return -EINVAL;
    lock_mark_dirty(&a->lock);
    std::uint32_t b = payload - sizeof(BlockHeader);
    BlockHeader* h = block(v, b);
    std::uint32_t sz = bsize(h);
    a->used_bytes.fetch_sub(sz, R);
    h->owner.store(0, R);
    h->size_flags.store(sz, R);  // free from here on
    const std::uint32_t nx = b + sz;
    if (nx < end(v, a) && !bused(block(v, nx))) {
        list_unlink(v, a, nx);
        sz += bsize(block(v, nx));
        h->size_flags.store(sz, R);  // merged with the next block
        fix_prev_of_next(v, a, b);
        a->blocks.fetch_sub(1, R);
    }
    const std::uint32_t pv = h->prev_size.load(R);
    if (pv && !bused(block(v, b - pv))) {
        const std::uint32_t p = b - pv;
        block(v, p)->size_flags.store(bsize(block(v, p)) + sz, R);  // merged into the previous one
        fix_prev_of_next(v, a, p);
        a->blocks.fetch_sub(1, R);
    } else {
        list_push(v, a, b);
    }
    lock_clear_dirty(&a->lock);
    return 0;
}

bool arena_rebuild_locked(const View& v, ArenaHeader* a) {
    lock_mark_dirty(&a->lock);
    // Walk the chain first without changing anything: a damaged chain is
    // left as it is for bpcheck to describe.
    for (std::uint32_t b = first(v, a); b != end(v, a);) {
        const BlockHeader* h = block(v, b);
        const std::uint32_t sz = bsize(h);
        if (sz < kMinBlock || sz % kBlockAlign || sz > end(v, a) - b || h->tag.load(R) != (b ^ kBlockTagXor)) {
            a->broken.store(1, R);
            return false;
        }
        b += sz;
    }
    a->free_head.store(0, R);
    std::uint32_t used = 0, blocks = 0, prev = 0, prev_off = 0;
    for (std::uint32_t b = first(v, a); b != end(v, a);) {
        BlockHeader* h = block(v, b);
        if (!bused(h) && prev_off && !bused(block(v, prev_off))) {
            // Two free neighbours (a merge cut short): join them.
            BlockHeader* p = block(v, prev_off);
            p->size_flags.store(bsize(p) + bsize(h), R);
            prev = bsize(p);
            b = prev_off + prev;
            continue;
        }
        h->prev_size.store(prev, R);
        if (bused(h)) used += bsize(h);
        ++blocks;
        prev = bsize(h);
        prev_off = b;
        b += prev;
    }
    // Free list in address order (pushed back to front).
    std::uint32_t last_free = 0;
    for (std::uint32_t b = first(v, a); b != end(v, a); b += bsize(block(v, b))) {
        if (bused(block(v, b))) continue;
        next_link(v, b)->store(0, R);
        prev_link(v, b)->store(last_free, R);
        if (last_free) next_link(v, last_free)->store(b, R); else a->free_head.store(b, R);
        last_free = b;
    }
    a->used_bytes.store(used, R);
    a->blocks.store(blocks, R);
    lock_clear_dirty(&a->lock);
    return true;
}

void arena_sweep_uncommitted_locked(const View& v, ArenaHeader* a) {
    for (bool again = true; again;) {
        again = false;
        for (std::uint32_t b = first(v, a); b != end(v, a); b += bsize(block(v, b))) {
            const BlockHeader* h = block(v, b);
            if (bused(h) && h->owner.load(R) != 0) {
                arena_free_locked(v, a, b + sizeof(BlockHeader));
                again = true;  // the chain changed around b: walk it again
                break;
            }
        }
    }
}

std::uint32_t arena_free_bytes(const View& v, const ArenaHeader* a) {
    const std::uint32_t room = bytes_of(v, a) - std::uint32_t(sizeof(ArenaHeader)), used = a->used_bytes.load(R);
    return used < room ? room - used : 0;
}

int arena_validate_locked(const View& v, const ArenaHeader* a, char* why, std::size_t n) {
    const std::uint32_t off = v.off_of(a);
    char name[32];
    if (off == v.layout.regions[kRegionCommon].offset) std::snprintf(name, sizeof name, "common arena");
    else std::snprintf(name, sizeof name, "local[%u] arena", (off - v.layout.regions[kRegionLocals].offset) / v.geo().local_window_size);
    auto bad = [&](const char* fmt, auto... args) {
        const int k = std::snprintf(why, n, "%s", name);
        if (k >= 0 && std::size_t(k) < n) std::snprintf(why + k, n - std::size_t(k), fmt, args...);
        return kCorrupt;
    };
    if (a->magic != kArenaMagic) return bad(".magic is 0x%08x, expected 0x%08x", a->magic, kArenaMagic);
    if (a->self != off) return bad(".self is %u, expected %u", a->self, off);
    if (a->size != bytes_of(v, a)) return bad(".size is %u, expected %u", a->size, bytes_of(v, a));
    // The chain: every step of alloc and free relies on sizes and prev
    // sizes that lead from block to block inside the arena.
    std::uint32_t frees = 0, prev = 0;
    for (std::uint32_t b = first(v, a); b != end(v, a);) {
        const BlockHeader* h = block(v, b);
        const std::uint32_t sz = bsize(h);
        if (sz < kMinBlock || sz % kBlockAlign || sz > end(v, a) - b) return bad(" block at %u: size %u does not fit", b, sz);
        if (h->tag.load(R) != (b ^ kBlockTagXor)) return bad(" block at %u: tag 0x%08x is wrong", b, h->tag.load(R));
        if (h->prev_size.load(R) != prev) return bad(" block at %u: prev_size %u, the previous block has %u", b, h->prev_size.load(R), prev);
        frees += !bused(h);
        prev = sz;
        b += sz;
    }
    // The free list: links to free blocks of this chain, no longer than
    // the free blocks (no cycle).
    std::uint32_t k = 0;
    for (std::uint32_t f = a->free_head.load(R); f; f = next_link(v, f)->load(R)) {
        if (f < first(v, a) || f > end(v, a) - kMinBlock || f % kBlockAlign || block(v, f)->tag.load(R) != (f ^ kBlockTagXor))
            return bad(".free_head list: link %u is not a block of this arena", f);
        if (bused(block(v, f))) return bad(".free_head list: block %u is in use", f);
        if (++k > frees) return bad(".free_head list: longer than the %u free blocks (a cycle)", frees);
    }
    return 0;
}

void arena_check(const View& v, const ArenaHeader* a, std::uint32_t off, std::uint32_t size,
                 const char* name, Report& r) {
    if (a->magic != kArenaMagic) return r.problem("%s.magic is 0x%08x, expected 0x%08x", name, a->magic, kArenaMagic);
    if (a->self != off) return r.problem("%s.self is %u, expected %u", name, a->self, off);
    if (a->size != size) return r.problem("%s.size is %u, expected %u", name, a->size, size);
    if (a->broken.load(R)) r.problem("%s.broken: marked damaged beyond repair by a recovery", name);
    if (a->lock.dirty.load(R)) r.problem("%s.lock.dirty: a change was left half-done", name);
    std::uint32_t used = 0, blocks = 0, frees = 0, prev = 0;
    bool prev_free = false;
    for (std::uint32_t b = first(v, a); b != end(v, a);) {
        const BlockHeader* h = block(v, b);
        const std::uint32_t sz = bsize(h);
        if (sz < kMinBlock || sz % kBlockAlign || sz > end(v, a) - b)
            return r.problem("%s block at %u: size %u does not fit the arena (chain broken)", name, b, sz);
        if (h->tag.load(R) != (b ^ kBlockTagXor))
            return r.problem("%s block at %u: tag 0x%08x is wrong (stray header)", name, b, h->tag.load(R));
        if (h->prev_size.load(R) != prev)
            r.problem("%s block at %u: prev_size %u, the previous block has %u", name, b, h->prev_size.load(R), prev);
        if (bused(h)) {
            used += sz;
            if (h->owner.load(R)) r.problem("%s block at %u: allocation never committed (owner token 0x%08x)", name, b, h->owner.load(R));
        } else {
            if (prev_free) r.problem("%s block at %u: free and its previous neighbour too (not merged)", name, b);
            ++frees;
        }
        prev_free = !bused(h);
        ++blocks;
        prev = sz;
        b += sz;
    }
    if (used != a->used_bytes.load(R)) r.problem("%s.used_bytes is %u, the blocks add up to %u", name, a->used_bytes.load(R), used);
    if (blocks != a->blocks.load(R)) r.problem("%s.blocks is %u, the chain has %u", name, a->blocks.load(R), blocks);
    std::uint32_t n = 0, back = 0;
    for (std::uint32_t f = a->free_head.load(R); f; f = next_link(v, f)->load(R)) {
        if (f < first(v, a) || f > end(v, a) - kMinBlock || f % kBlockAlign || block(v, f)->tag.load(R) != (f ^ kBlockTagXor))
            return r.problem("%s free list: link %u is not a block of this arena", name, f);
        if (bused(block(v, f))) r.problem("%s free list: block %u is in use", name, f);
        if (prev_link(v, f)->load(R) != back) r.problem("%s free list: block %u links back to %u, not %u", name, f, prev_link(v, f)->load(R), back);
        back = f;
        if (++n > frees) return r.problem("%s free list: longer than the %u free blocks (cycle?)", name, frees);
    }
    if (n != frees) r.problem("%s free list: %u entries, the chain has %u free blocks", name, n, frees);
}

}  // namespace chm::bp
