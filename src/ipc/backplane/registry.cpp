// The name registry: a fixed table of named objects (shared memory
// segments now; remote semaphores, message queues and the state-variable
// table later), each with its storage in common memory or in one RTPU's
// local window. Entries change only under Header::registry_lock; each
// change is bracketed by an odd `seq`, so lookups read committed entries
// without the lock, and a holder that dies mid-change leaves an odd entry
// that registry_repair_locked() finishes or undoes.
//
// Invariant the repair relies on: every arena allocation is made by a
// holder of the registry lock and committed (block owner = 0) before it is
// released, so a used block that still has an owner while we hold the lock
// belongs to a holder that died.
#include <cerrno>
#include <cstring>

#include "chimera/bp.h"
#include "ipc/backplane/backplane.hpp"
#include "ipc/backplane/stop_point.hpp"

namespace chm::bp {

namespace {

constexpr auto R = std::memory_order_relaxed;

void begin_change(RegistryEntry* e) {
    e->seq.fetch_add(1, R);
    std::atomic_thread_fence(std::memory_order_release);
}
void end_change(RegistryEntry* e) { e->seq.fetch_add(1, std::memory_order_release); }

void write_name(RegistryEntry* e, const char* name, std::size_t len) {
    std::uint32_t w[8] = {};
    std::memcpy(w, name, len);
    for (unsigned i = 0; i < 8; ++i) e->name_words[i].store(w[i], R);
}

bool name_is(const RegistryEntry* e, const char* name, std::size_t len) {
    std::uint32_t w[8] = {};
    std::memcpy(w, name, len);
    for (unsigned i = 0; i < 8; ++i)
        if (e->name_words[i].load(R) != w[i]) return false;
    return true;
}

void clear_entry(RegistryEntry* e) {
    e->kind.store(0, R);
    e->offset.store(0, R);
    e->size.store(0, R);
    e->where.store(0, R);
    e->owner.store(0, R);
    e->attached.store(0, R);
    for (auto& w : e->name_words) w.store(0, R);
    e->state.store(static_cast<std::uint32_t>(EntryState::Free), R);
}

EntryState state_of(const RegistryEntry* e) { return static_cast<EntryState>(e->state.load(R)); }

// Marks the registry dirty for a scope, unless an enclosing scope (the
// repair) already did.
struct DirtyScope {
    Lock* l;
    bool was;
    explicit DirtyScope(const View& v) : l(&v.hdr()->registry_lock), was(l->dirty.load(R) != 0) {
        if (!was) lock_mark_dirty(l);
    }
    ~DirtyScope() {
        if (!was) lock_clear_dirty(l);
    }
};

// The destroyed entry `i` is no longer attached anywhere: free its storage
// and the entry.
void final_free_locked(const View& v, std::uint32_t i, std::uint32_t me) {
    RegistryEntry* e = v.entry(i);
    DirtyScope dirty(v);
    begin_change(e);
    ArenaHeader* a = v.arena_for(e->where.load(R));
    if (a && arena_lock(v, a, me) == 0) {
        // Re-checked because a repair may run this twice.
        if (arena_block_used(v, a, e->offset.load(R), e->size.load(R))) arena_free_locked(v, a, e->offset.load(R));
        arena_unlock(a);
    }
    clear_entry(e);
    end_change(e);
}

}  // namespace

bool valid_name(const char* name, std::size_t* len) {
    if (!name) return false;
    *len = ::strnlen(name, kNameMax + 1);
    return *len >= 1 && *len <= kNameMax;
}

void read_name(const RegistryEntry* e, char out[kNameMax + 1]) {
    std::uint32_t w[8];
    for (unsigned i = 0; i < 8; ++i) w[i] = e->name_words[i].load(R);
    std::memcpy(out, w, kNameMax + 1);
    out[kNameMax] = 0;
}

int registry_lock(const View& v, std::uint32_t me) {
    Lock* l = &v.hdr()->registry_lock;
    const int r = lock_acquire(v, l, me, kInternalPollNs, kInternalTimeoutNs);
    if (r == -ETIMEDOUT) return r;
    if (r == -EOWNERDEAD && l->dirty.load(std::memory_order_acquire)) registry_repair_locked(v, me);
    CHM_STOP_POINT("bp.registry.locked");
    return 0;
}

void registry_unlock(const View& v) { lock_release(&v.hdr()->registry_lock); }

int registry_find_locked(const View& v, const char* name, std::uint32_t kind) {
    std::size_t len;
    if (!valid_name(name, &len)) return -ENOENT;
    for (std::uint32_t i = 0; i < v.geo().registry_capacity; ++i) {
        const RegistryEntry* e = v.entry(i);
        if (state_of(e) == EntryState::Live && name_is(e, name, len) &&
            (kind == kKindNone || e->kind.load(R) == kind))
            return int(i);
    }
    return -ENOENT;
}

int registry_find_offset_locked(const View& v, std::uint32_t offset) {
    for (std::uint32_t i = 0; i < v.geo().registry_capacity; ++i) {
        const RegistryEntry* e = v.entry(i);
        if (state_of(e) != EntryState::Free && e->offset.load(R) == offset) return int(i);
    }
    return -ENOENT;
}

int registry_lookup(const View& v, const char* name, std::uint32_t kind, EntryInfo* out) {
    std::size_t len;
    if (!valid_name(name, &len)) return -ENOENT;
    for (std::uint32_t i = 0; i < v.geo().registry_capacity; ++i) {
        const RegistryEntry* e = v.entry(i);
        for (int tries = 0; tries < 100; ++tries) {
            const std::uint32_t s1 = e->seq.load(std::memory_order_acquire);
            if (s1 & 1) continue;  // changing right now
            const bool hit = state_of(e) == EntryState::Live && name_is(e, name, len) &&
                             (kind == kKindNone || e->kind.load(R) == kind);
            EntryInfo info{i, e->kind.load(R), e->offset.load(R), e->size.load(R), e->where.load(R), e->owner.load(R)};
            std::atomic_thread_fence(std::memory_order_acquire);
            if (e->seq.load(R) != s1) continue;
            if (!hit) break;
            *out = info;
            return 0;
        }
    }
    return -ENOENT;
}

int registry_create_locked(const View& v, std::uint32_t me, std::uint32_t kind, const char* name,
                           std::uint32_t size, std::uint32_t where, std::uint32_t attach_slot,
                           EntryInfo* out) {
    std::size_t len;
    if (!name) return -EINVAL;
    if (!valid_name(name, &len)) return len == 0 ? -EINVAL : -ENAMETOOLONG;
    ArenaHeader* a = v.arena_for(where);
    if (size == 0 || !a || kind == kKindNone || kind >= kKindMax || attach_slot >= v.slots()) return -EINVAL;
    if (registry_find_locked(v, name, kKindNone) >= 0) return -EEXIST;
    std::uint32_t i = 0;
    const std::uint32_t cap = v.geo().registry_capacity;
    while (i < cap && (state_of(v.entry(i)) != EntryState::Free || (v.entry(i)->seq.load(R) & 1))) ++i;
    if (i == cap) return -ENOSPC;

    Lock* rl = &v.hdr()->registry_lock;
    lock_mark_dirty(rl);  // before the allocation: see the invariant above
    int r = arena_lock(v, a, me);
    if (r) {
        lock_clear_dirty(rl);
        return r;
    }
    const std::uint32_t off = arena_alloc_locked(v, a, size, me);
    arena_unlock(a);
    if (!off) {
        lock_clear_dirty(rl);
        return -ENOMEM;
    }
    std::memset(v.base + off, 0, size);  // a new object starts zeroed
    RegistryEntry* e = v.entry(i);
    begin_change(e);
    CHM_STOP_POINT("registry.create.locked");  // mid-change: allocated, the entry half written
    e->kind.store(kind, R);
    e->offset.store(off, R);
    e->size.store(size, R);
    e->where.store(where, R);
    e->owner.store(me, R);
    e->attached.store(1u << attach_slot, R);
    write_name(e, name, len);
    e->state.store(static_cast<std::uint32_t>(EntryState::Live), R);
    arena_commit(v, off);
    end_change(e);
    lock_clear_dirty(rl);
    *out = EntryInfo{i, kind, off, size, where, me};
    return 0;
}

void registry_destroy_locked(const View& v, std::uint32_t i, std::uint32_t me) {
    RegistryEntry* e = v.entry(i);
    if (state_of(e) != EntryState::Live) return;
    {
        DirtyScope dirty(v);
        begin_change(e);
        e->state.store(static_cast<std::uint32_t>(EntryState::Destroying), R);
        end_change(e);
    }
    if (e->attached.load(R) == 0) final_free_locked(v, i, me);
}

void registry_ref_locked(Attachment& a, std::uint32_t index) {
    a.entry(index)->attached.fetch_or(1u << a.slot, R);
    ++a.local_refs[index];
}

int registry_unref_locked(Attachment& a, std::uint32_t offset, std::uint32_t kind) {
    const int i = registry_find_offset_locked(a, offset);
    if (i < 0 || a.entry(std::uint32_t(i))->kind.load(R) != kind || !a.local_refs[i]) return -EINVAL;
    if (--a.local_refs[i] == 0) {
        a.objects[i] = Attachment::OpenObject{};  // its handles stop resolving here
        registry_detach_locked(a, std::uint32_t(i), a.slot, a.token);
    }
    return 0;
}

void registry_detach_locked(const View& v, std::uint32_t i, std::uint32_t slot, std::uint32_t me) {
    RegistryEntry* e = v.entry(i);
    e->attached.fetch_and(~(1u << slot), R);
    if (state_of(e) == EntryState::Destroying && e->attached.load(R) == 0) final_free_locked(v, i, me);
}

void registry_repair_locked(const View& v, std::uint32_t me) {
    Lock* rl = &v.hdr()->registry_lock;
    lock_mark_dirty(rl);
    const std::uint32_t cap = v.geo().registry_capacity;
    // Slots that are FREE or DEAD cannot have anything attached (a dead
    // slot is recovered before it is joined again).
    std::uint32_t gone = 0;
    for (std::uint32_t s = 0; s < v.slots(); ++s) {
        const SlotState st = status_state(v.rtpu(s)->status.load(std::memory_order_acquire));
        if (st == SlotState::Free || st == SlotState::Dead) gone |= 1u << s;
    }
    for (std::uint32_t i = 0; i < cap; ++i) {
        RegistryEntry* e = v.entry(i);
        if (e->seq.load(R) & 1) {
            switch (state_of(e)) {
            case EntryState::Live: {  // a create got as far as publishing: finish it
                ArenaHeader* a = v.arena_for(e->where.load(R));
                if (a && arena_block_used(v, a, e->offset.load(R), e->size.load(R))) arena_commit(v, e->offset.load(R));
                break;
            }
            case EntryState::Destroying:
                break;  // freed below if nobody holds it
            default:  // a create cut short, or an entry being cleared: undo
                clear_entry(e);
                break;
            }
            end_change(e);
        }
        if (state_of(e) != EntryState::Free) e->attached.fetch_and(~gone, R);
    }
    ArenaHeader* arenas[kMaxSlots + 1];
    std::uint32_t n = 0;
    arenas[n++] = v.common_arena();
    for (std::uint32_t s = 0; s < v.slots(); ++s) arenas[n++] = v.local_arena(s);
    for (std::uint32_t k = 0; k < n; ++k) {
        if (arena_lock(v, arenas[k], me) != 0) continue;  // broken: nothing to sweep safely
        arena_sweep_uncommitted_locked(v, arenas[k]);
        arena_unlock(arenas[k]);
    }
    for (std::uint32_t i = 0; i < cap; ++i) {
        RegistryEntry* e = v.entry(i);
        if (state_of(e) == EntryState::Destroying && e->attached.load(R) == 0) final_free_locked(v, i, me);
    }
    lock_clear_dirty(rl);
}

}  // namespace chm::bp

// ------------------------------------------------- the public walk (bp.h)

extern "C" int chm_bp_objects(chm_bp_object_t* out, int max, int* total) {
    using namespace chm::bp;
    if (max < 0 || (max > 0 && !out)) {
        set_error("chm_bp_objects: %s", max < 0 ? "max < 0" : "out is NULL");
        return -EINVAL;
    }
    const Attachment* a = current();
    if (!a) {
        set_error("chm_bp_objects: not attached to a backplane");
        return -ENOTCONN;
    }
    // Each entry is copied between two even, equal `seq` reads (a change in
    // progress is retried), and what it says is checked before it is
    // passed on: the file is shared with every process that may write it.
    int filled = 0, live = 0;
    for (std::uint32_t i = 0; i < a->geo().registry_capacity; ++i) {
        const RegistryEntry* e = a->entry(i);
        bool ok = false;
        chm_bp_object_t o{};
        std::uint32_t where = 0, owner = 0;
        for (int tries = 0; tries < 100 && !ok; ++tries) {
            const std::uint32_t s1 = e->seq.load(std::memory_order_acquire);
            if (s1 & 1) continue;
            if (state_of(e) != EntryState::Live) break;
            read_name(e, o.name);
            o.kind = e->kind.load(R);
            o.size = e->size.load(R);
            where = e->where.load(R);
            owner = e->owner.load(R);
            o.attached = e->attached.load(R);
            std::atomic_thread_fence(std::memory_order_acquire);
            ok = e->seq.load(R) == s1;
        }
        if (!ok) continue;  // free, or changing for 100 reads: not a live object now
        if (o.kind == kKindNone || o.kind >= kKindMax || !o.name[0] ||
            (where != kWhereCommon && where >= a->slots()))
            continue;  // not an object any process could have made: not shown
        o.where = where == kWhereCommon ? -1 : int32_t(where);
        const std::uint32_t creator = token_slot(owner);
        o.creator = owner && creator < a->slots() ? int32_t(creator) : -1;
        const std::uint32_t slot_mask = a->slots() >= 32 ? 0xFFFFFFFFu : (1u << a->slots()) - 1;
        o.attached &= slot_mask;
        ++live;
        if (filled < max) out[filled++] = o;
    }
    if (total) *total = live;
    return filled;
}
