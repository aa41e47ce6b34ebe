// Validation of what a process is about to trust in a backplane file,
// beyond the header (file.cpp): at attach, the structures every attached
// process walks (RTPU table, express-mail rings, arena headers, registry
// entries); at open, an object's registry entry (its payload inside its
// arena, an allocated block, large enough for its kind). A bad field gives
// kCorrupt (-EBADMSG) with a text naming the structure and the field: a
// corrupt file is refused, never followed outside the map.
//
// Only what no live process changes mid-operation is checked at attach
// (slot states and kinds, ring geometry, arena headers, committed registry
// entries read under their seq): attaching to a busy system must not
// refuse a structure caught in the middle of a legitimate change. The
// chains and indices that do change are checked under their own locks
// (arena_lock, the objects' opens) and by chm_bp_validate on a whole file.
#include <cerrno>
#include <cstdarg>
#include <cstdio>
#include <cstring>

#include <unistd.h>

#include "chimera/bp.h"
#include "ipc/backplane/backplane.hpp"

namespace chm::bp {

int corrupt(char* why, std::size_t n, const char* fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    std::vsnprintf(why, n, fmt, ap);
    va_end(ap);
    return kCorrupt;
}

namespace {

constexpr auto R = std::memory_order_relaxed;


const char* arena_text(std::uint32_t where) { return where == kWhereCommon ? "common memory" : "an RTPU window"; }

// A committed entry's words, read between two equal even seq values (an
// entry changes only under the registry lock, bracketed by an odd seq).
// False when it kept changing.
struct EntryWords {
    std::uint32_t state, kind, offset, size, where;
};
bool read_entry(const RegistryEntry* e, EntryWords* w) {
    for (int tries = 0; tries < 100; ++tries) {
        const std::uint32_t s1 = e->seq.load(std::memory_order_acquire);
        if (s1 & 1) continue;
        *w = EntryWords{e->state.load(R), e->kind.load(R), e->offset.load(R), e->size.load(R), e->where.load(R)};
        std::atomic_thread_fence(std::memory_order_acquire);
        if (e->seq.load(R) == s1) return true;
    }
    return false;
}

int check_payload(const View& v, std::uint32_t i, const EntryWords& w, char* why, std::size_t n) {
    if (w.where != kWhereCommon && w.where >= v.slots())
        return corrupt(why, n, "registry[%u].where is %u: neither common memory nor an RTPU slot 0..%u", i, w.where,
                       v.slots() - 1);
    // 64-bit sums: offset + size must not wrap at 32 bits into the arena.
    const std::uint64_t lo = v.arena_offset(w.where), hi = lo + v.arena_size(w.where);
    const std::uint64_t first = lo + sizeof(ArenaHeader) + sizeof(BlockHeader);
    if (w.offset < first || w.size == 0 || std::uint64_t(w.offset) + w.size > hi)
        return corrupt(why, n, "registry[%u].offset %u + size %u lies outside %s [%llu, %llu)", i, w.offset, w.size,
                       arena_text(w.where), static_cast<unsigned long long>(first), static_cast<unsigned long long>(hi));
    if (!arena_block_used(v, v.arena_for(w.where), w.offset, w.size))
        return corrupt(why, n, "registry[%u].offset %u is not an allocated block of %u bytes in %s", i, w.offset,
                       w.size, arena_text(w.where));
    return 0;
}

}  // namespace

int validate_structure(const View& v, char* why, std::size_t n) {
    const Geometry& g = v.geo();
    for (std::uint32_t s = 0; s < v.slots(); ++s) {
        const RtpuEntry* e = v.rtpu(s);
        const std::uint32_t state = e->status.load(R) & 0xFF, kind = e->kind.load(R);
        if (state >= kStateCount) return corrupt(why, n, "rtpu[%u].status: state %u is not a slot state", s, state);
        if (kind > std::uint32_t(SlotKind::Host)) return corrupt(why, n, "rtpu[%u].kind is %u, not RTPU or HOST", s, kind);
        const RingHeader* ring = v.ring(s);
        if (ring->capacity != g.ring_records)
            return corrupt(why, n, "ring[%u].capacity is %u, the header says %u", s, ring->capacity, g.ring_records);
        if (ring->record_size != g.ring_record_size)
            return corrupt(why, n, "ring[%u].record_size is %u, the header says %u", s, ring->record_size,
                           g.ring_record_size);
    }
    for (std::uint32_t k = 0; k <= v.slots(); ++k) {
        const std::uint32_t where = k == v.slots() ? kWhereCommon : k;
        const ArenaHeader* a = v.arena_for(where);
        char name[32];
        if (where == kWhereCommon) std::snprintf(name, sizeof name, "common arena");
        else std::snprintf(name, sizeof name, "local[%u] arena", k);
        if (a->magic != kArenaMagic) return corrupt(why, n, "%s.magic is 0x%08x, expected 0x%08x", name, a->magic, kArenaMagic);
        if (a->self != v.arena_offset(where))
            return corrupt(why, n, "%s.self is %u, expected %u", name, a->self, v.arena_offset(where));
        if (a->size != v.arena_size(where))
            return corrupt(why, n, "%s.size is %u, expected %u", name, a->size, v.arena_size(where));
    }
    for (std::uint32_t i = 0; i < g.registry_capacity; ++i) {
        EntryWords w;
        if (!read_entry(v.entry(i), &w)) continue;  // mid-change: its repair or its writer finishes it
        if (w.state > std::uint32_t(EntryState::Destroying))
            return corrupt(why, n, "registry[%u].state is %u, not FREE, LIVE or DESTROYING", i, w.state);
        if (w.state == std::uint32_t(EntryState::Free)) continue;
        if (w.kind == kKindNone || w.kind >= kKindMax)
            return corrupt(why, n, "registry[%u].kind is %u: not an object kind", i, w.kind);
        if (int r = check_payload(v, i, w, why, n)) return r;
    }
    return 0;
}

int validate_fresh_token(const View& v, std::uint32_t token, char* why, std::size_t n) {
    const std::uint32_t slot = token_slot(token), rt = make_token(slot, token_gen(token), true);
    auto named = [&](const Lock& l) {
        const std::uint32_t t = l.token.load(R);
        return t == token || t == rt;
    };
    if (named(v.hdr()->registry_lock))
        return corrupt(why, n, "header.registry_lock.token 0x%08x names slot %u generation %u, which did not exist "
                       "until this join", v.hdr()->registry_lock.token.load(R), slot, token_gen(token));
    for (std::uint32_t k = 0; k <= v.slots(); ++k) {
        const std::uint32_t where = k == v.slots() ? kWhereCommon : k;
        if (named(v.arena_for(where)->lock)) {
            char name[32];
            if (where == kWhereCommon) std::snprintf(name, sizeof name, "common arena");
            else std::snprintf(name, sizeof name, "local[%u] arena", k);
            return corrupt(why, n, "%s.lock.token names slot %u generation %u, which did not exist until this join", name,
                           slot, token_gen(token));
        }
        if (k < v.slots() && named(v.ring(k)->lock))
            return corrupt(why, n, "ring[%u].lock.token names slot %u generation %u, which did not exist until this join", k,
                           slot, token_gen(token));
    }
    return 0;
}

int entry_payload(const View& v, std::uint32_t index, std::uint32_t min_size, std::uint32_t* off,
                  std::uint32_t* size, char* why, std::size_t n) {
    if (index >= v.geo().registry_capacity) return corrupt(why, n, "registry index %u out of range", index);
    EntryWords w;
    if (!read_entry(v.entry(index), &w)) return corrupt(why, n, "registry[%u].seq keeps changing", index);
    if (int r = check_payload(v, index, w, why, n)) return r;
    if (w.size < min_size)
        return corrupt(why, n, "registry[%u].size is %u, smaller than the %u bytes of its kind", index, w.size, min_size);
    *off = w.offset;
    *size = w.size;
    return 0;
}

int validate_file(const View& v, char* why, std::size_t n) {
    if (int r = validate_structure(v, why, n)) return r;
    for (std::uint32_t k = 0; k <= v.slots(); ++k) {
        const ArenaHeader* a = v.arena_for(k == v.slots() ? kWhereCommon : k);
        if (a->lock.token.load(R) != 0) continue;  // held: its holder or robber repairs it first
        if (int r = arena_validate_locked(v, a, why, n)) return r;
    }
    for (std::uint32_t i = 0; i < v.geo().registry_capacity; ++i) {
        EntryWords w;
        if (!read_entry(v.entry(i), &w) || w.state != std::uint32_t(EntryState::Live)) continue;
        char name[kNameMax + 1];
        read_name(v.entry(i), name);
        char label[kNameMax + 32];
        std::snprintf(label, sizeof label, "registry[%u] \"%s\"", i, name);
        int r = 0;
        if (w.kind == kKindMsgQueue) r = chm::ipc::msgq::validate_entry(v, w.offset, w.size, label, why, n);
        else if (w.kind == kKindRemoteSem) r = chm::ipc::rsem_validate(v, w.offset, w.size, label, why, n);
        else if (w.kind == kKindStateVars) r = chm::ipc::svar_validate(v, w.offset, w.size, label, why, n);
        if (r) return r;
    }
    return 0;
}

}  // namespace chm::bp

using namespace chm::bp;

extern "C" int chm_bp_validate(const char* path) {
    char defpath[4096];
    if (int r = path_or_default(&path, defpath, sizeof defpath)) return r;
    View v;
    int fd = -1;
    char why[768];
    // Read-only, like the checker: callers that go on to attach make the
    // trust check themselves (chimera start and status do it first).
    int r = map_file(path, false, &v, &fd, why, sizeof why, false);
    if (r == 0) {
        r = validate_file(v, why, sizeof why);
        unmap(&v);
        ::close(fd);
    }
    if (r) set_error("backplane %s: %s", path, why);
    return r;
}
