// The backplane checker behind chimera-bpcheck and the tests: reads a
// mapped file (read-only is enough) and reports, one line each, every
// inconsistency it finds, naming the structure and field.
#include <cstdarg>
#include <cstdio>
#include <cstring>

#include "ipc/backplane/backplane.hpp"
#include "ipc/backplane/stop_point.hpp"
#include "ipc/xmail/xmail.hpp"

namespace chm::bp {

namespace {

constexpr auto R = std::memory_order_relaxed;

const char* state_name(std::uint32_t s) {
    static const char* const kNames[] = {"FREE", "JOINING", "RUNNING", "LEAVING", "DEAD", "RECOVERING"};
    return s < kStateCount ? kNames[s] : "?";
}


// A request of a sender that is dead or gone (claimed, written, posted, a
// reply never read, set aside as stale) in ring `s`: its recovery or its
// leave gives every such record up (xmail::withdraw), so one left holds a
// record of the ring until that ring's server next wakes. Records being
// served or abandoned are the ring's server's.
void check_ring_records(const View& v, std::uint32_t s, Report& r) {
    using namespace chm::xmail;
    if (ring_record_size(v) < sizeof(Record)) return;  // no express mail on this backplane
    RingHeader* ring = v.ring(s);
    for (std::uint32_t i = 0; i < ring_capacity(v); ++i) {
        const Record* rec = record_at(v, ring, i);
        const Phase p = phase_of(rec->state.load(std::memory_order_acquire));
        if (p != kWriting && p != kPosted && p != kReplied && p != kStale) continue;
        const std::uint32_t owner = rec->owner.load(R);
        if (token_alive(v, owner, true)) continue;
        static const char* const kPhase[] = {"FREE", "WRITING", "POSTED", "SERVING", "REPLIED", "ABANDONED", "STALE"};
        r.problem("ring[%u] record %u: %s, its sender (slot %u generation %u) is no live process: not given up", s, i,
                  kPhase[p], token_slot(owner), token_gen(owner));
    }
}

// One slot's words as of one instant. A checker runs beside live
// processes: a slot that joins, leaves or is recovered while its words are
// read could pair a status with another status's pid or recoverer. Each
// of those changes moves the status word before the words it then writes
// (the pid is named after the JOINING CAS, vacated after the LEAVING or
// RECOVERING CAS, the recoverer cleared after the DEAD CAS), so words read
// between two equal readings of the status belong to that status.
struct SlotWords {
    std::uint32_t status, kind, pid, recoverer;
    std::uint64_t pid_start;
};

bool read_slot(const RtpuEntry* e, SlotWords* w) {
    constexpr auto A = std::memory_order_acquire;
    for (int attempt = 0; attempt < 64; ++attempt) {
        w->status = e->status.load(A);
        if (status_state(w->status) == SlotState::Recovering) CHM_STOP_POINT("bp.check.read_recovering");
        w->kind = e->kind.load(A);
        w->pid = e->pid.load(A);
        w->pid_start = e->pid_start.load();
        w->recoverer = e->recoverer.load(A);
        if (e->status.load(A) == w->status) return true;
    }
    return false;  // changing all the time: a live slot, judged at the next check
}

// The pid word a slot in `state` (generation gen) may hold at one instant,
// besides a live process (layout.hpp, "the pid word"): a joiner that has
// not named itself yet holds the previous generation's vacancy (0 in a new
// file), one given up by a judge this generation's; a leaver vacates its
// generation before the slot is FREE.
bool pid_between_steps(SlotState state, std::uint32_t gen, std::uint32_t pid) {
    const std::uint32_t prev = (gen - 1) & 0xFFFFFF;
    switch (state) {
    case SlotState::Joining: return pid == vacant_pid(gen) || pid == vacant_pid(prev) || (pid == 0 && prev == 0);
    case SlotState::Leaving: return pid == vacant_pid(gen);
    default: return false;
    }
}

void check_slot(std::uint32_t s, const SlotWords& w, Report& r, Summary* sum) {
    const std::uint32_t state = w.status & 0xFF, gen = status_gen(w.status);
    if (state >= kStateCount) {
        r.problem("rtpu[%u].status: state %u is not a slot state", s, state);
        return;
    }
    if (w.kind > std::uint32_t(SlotKind::Host)) r.problem("rtpu[%u].kind is %u, not RTPU or HOST", s, w.kind);
    switch (static_cast<SlotState>(state)) {
    case SlotState::Joining:
    case SlotState::Running:
    case SlotState::Leaving:
        if (w.kind == std::uint32_t(SlotKind::Host)) ++sum->hosts; else ++sum->rtpus;
        if (pid_between_steps(static_cast<SlotState>(state), gen, w.pid)) break;
        if (!pid_named(w.pid)) r.problem("rtpu[%u]: %s without a pid (pid word %#x)", s, state_name(state), w.pid);
        else if (!proc_alive(int(w.pid), w.pid_start))
            r.problem("rtpu[%u]: %s but process %u is dead (not recovered yet)", s, state_name(state), w.pid);
        break;
    case SlotState::Recovering:
        ++sum->dead;
        if (w.recoverer == 0)
            r.problem("rtpu[%u]: RECOVERING with no recoverer (an attempt ran out of time: the next survivor "
                      "to look takes it over)", s);
        else if (!recoverer_alive(w.recoverer))
            r.problem("rtpu[%u]: RECOVERING but its recoverer (process %u) is dead (not taken over yet)", s,
                      recoverer_pid_of(w.recoverer));
        break;
    case SlotState::Dead:
        ++sum->dead;
        [[fallthrough]];
    case SlotState::Free:
        // A vacancy names its generation (layout.hpp); 0 only in a new file.
        if (w.pid != vacant_pid(gen) && !(w.pid == 0 && gen == 0))
            r.problem("rtpu[%u]: %s (generation %u) but the pid word is %#x, not its vacancy", s,
                      state_name(state), gen, w.pid);
        break;
    }
}

void check_table(const View& v, Report& r, Summary* sum) {
    char what[64];
    for (std::uint32_t s = 0; s < v.slots(); ++s) {
        const RtpuEntry* e = v.rtpu(s);
        if (!std::memchr(e->name, 0, sizeof e->name)) r.problem("rtpu[%u].name is not NUL-terminated", s);
        SlotWords w;
        if (read_slot(e, &w)) check_slot(s, w, r, sum);
        const RingHeader* ring = v.ring(s);
        if (ring->capacity != v.geo().ring_records || ring->record_size != v.geo().ring_record_size)
            r.problem("ring[%u]: capacity %u x %u bytes, the header says %u x %u", s, ring->capacity, ring->record_size,
                      v.geo().ring_records, v.geo().ring_record_size);
        std::snprintf(what, sizeof what, "ring[%u].lock", s);
        check_lock(v, ring->lock, what, r);
        check_ring_records(v, s, r);
    }
}

// Where the payload of `e` may lie.
bool payload_ok(const View& v, const RegistryEntry* e, std::uint32_t i, Report& r) {
    const std::uint32_t where = e->where.load(R), off = e->offset.load(R), size = e->size.load(R);
    const ArenaHeader* a = v.arena_for(where);
    if (!a) {
        r.problem("registry[%u].where is %u: neither common memory nor a slot", i, where);
        return false;
    }
    const std::uint32_t lo = v.off_of(a), hi = lo + v.arena_size(where);  // the layout's, not the file's
    if (off < lo + sizeof(ArenaHeader) || off >= hi || size == 0 || size > hi - off) {
        r.problem("registry[%u].offset %u size %u lies outside %s [%u, %u)", i, off, size,
                  where == kWhereCommon ? "common memory" : "its RTPU window", lo, hi);
        return false;
    }
    if (!arena_block_used(v, a, off, size)) {
        r.problem("registry[%u].offset %u is not an allocated block of %u bytes", i, off, size);
        return false;
    }
    return true;
}

// The object's own structure, by its kind's checker (those without one,
// like shared memory, are plain bytes).
void check_object(const View& v, const RegistryEntry* e, std::uint32_t i, const char* name, Report& r) {
    char label[kNameMax + 32];
    std::snprintf(label, sizeof label, "registry[%u] \"%s\"", i, name);
    const std::uint32_t off = e->offset.load(R), size = e->size.load(R);
    switch (e->kind.load(R)) {
    case kKindRemoteSem: chm::ipc::rsem_check(v, off, size, label, r); break;
    case kKindMsgQueue: chm::ipc::msgq::check_entry(v, off, size, label, r); break;
    case kKindStateVars: chm::ipc::svar_check(v, off, size, label, r); break;
    default: break;
    }
}

void check_registry(const View& v, Report& r, Summary* sum) {
    const std::uint32_t cap = v.geo().registry_capacity;
    std::uint32_t live_mask = 0;
    for (std::uint32_t s = 0; s < v.slots(); ++s) {
        const auto st = status_state(v.rtpu(s)->status.load(R));
        if (st == SlotState::Joining || st == SlotState::Running || st == SlotState::Leaving || st == SlotState::Recovering)
            live_mask |= 1u << s;
    }
    for (std::uint32_t i = 0; i < cap; ++i) {
        const RegistryEntry* e = v.entry(i);
        if (e->seq.load(R) & 1) r.problem("registry[%u].seq is odd: a change was left half-done", i);
        const std::uint32_t state = e->state.load(R);
        if (state > std::uint32_t(EntryState::Destroying)) {
            r.problem("registry[%u].state is %u, not FREE, LIVE or DESTROYING", i, state);
            continue;
        }
        if (state == std::uint32_t(EntryState::Free)) {
            if (e->offset.load(R) || e->attached.load(R)) r.problem("registry[%u]: FREE but not cleared", i);
            continue;
        }
        char name[kNameMax + 1];
        read_name(e, name);
        const std::uint32_t kind = e->kind.load(R);
        if (kind == kKindNone || kind >= kKindMax) r.problem("registry[%u].kind is %u: not an object kind", i, kind);
        std::size_t len;
        if (!valid_name(name, &len) || reinterpret_cast<const char*>(e->name_words)[kNameMax] != 0)
            r.problem("registry[%u].name is empty or not NUL-terminated", i);
        const bool payload = payload_ok(v, e, i, r);
        const std::uint32_t att = e->attached.load(R);
        if (att & ~live_mask) r.problem("registry[%u] \"%s\".attached 0x%08x names slots that are not live", i, name, att);
        if (state == std::uint32_t(EntryState::Destroying)) {
            ++sum->destroying;
            if (att == 0) r.problem("registry[%u] \"%s\": destroyed, attached nowhere, yet not freed", i, name);
            continue;
        }
        ++sum->objects;
        if (payload) check_object(v, e, i, name, r);
        for (std::uint32_t j = 0; j < i; ++j) {
            const RegistryEntry* o = v.entry(j);
            char other[kNameMax + 1];
            read_name(o, other);
            if (o->state.load(R) == std::uint32_t(EntryState::Live) && std::strcmp(other, name) == 0)
                r.problem("registry[%u] and registry[%u] are both called \"%s\"", j, i, name);
        }
    }
}

}  // namespace

void check_lock(const View& v, const Lock& l, const char* what, Report& r) {
    const std::uint32_t t = l.token.load(R);
    if (t == 0) {
        if (l.dirty.load(R)) r.problem("%s.dirty is set on a free lock", what);
        return;
    }
    if (t == kOrphanToken)
        r.problem("%s: left mid-change by a task that ended inside a call (task 0x%08x; its next user repairs it)",
                  what, l.owner_task.load(R));
    else if (!token_alive(v, t, true))
        r.problem("%s: held by a dead owner (token 0x%08x: slot %u generation %u%s)", what, t, token_slot(t),
                  token_gen(t), token_recovery(t) ? ", recovery" : "");
}

void Report::problem(const char* fmt, ...) {
    ++problems;
    if (!emit) return;
    char line[400];
    va_list ap;
    va_start(ap, fmt);
    std::vsnprintf(line, sizeof line, fmt, ap);
    va_end(ap);
    emit(ctx, line);
}

void check_backplane(const View& v, Report& r, Summary* sum) {
    Summary local;
    if (!sum) sum = &local;
    const Header* h = v.hdr();
    const Layout& l = v.layout;  // the validated copy
    check_table(v, r, sum);
    check_lock(v, h->registry_lock, "header.registry_lock", r);
    // A live holder may be in the middle of a change: check only a
    // registry nobody (alive) holds.
    const std::uint32_t t = h->registry_lock.token.load(R);
    if (t == 0 || !token_alive(v, t, true)) check_registry(v, r, sum);
    char name[48];
    const ArenaHeader* c = v.common_arena();
    check_lock(v, c->lock, "common.lock", r);
    arena_check(v, c, l.regions[kRegionCommon].offset, l.geo.common_size, "common", r);
    sum->common_size = l.geo.common_size - sizeof(ArenaHeader);
    sum->common_used = c->used_bytes.load(R);
    for (std::uint32_t s = 0; s < v.slots(); ++s) {
        const ArenaHeader* a = v.local_arena(s);
        std::snprintf(name, sizeof name, "local[%u].lock", s);
        check_lock(v, a->lock, name, r);
        std::snprintf(name, sizeof name, "local[%u]", s);
        arena_check(v, a, l.regions[kRegionLocals].offset + s * l.geo.local_window_size, l.geo.local_window_size,
                    name, r);
        sum->local_size += l.geo.local_window_size - sizeof(ArenaHeader);
        sum->local_used += a->used_bytes.load(R);
    }
}

}  // namespace chm::bp
