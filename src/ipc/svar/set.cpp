// A task's set of state variables (chimera/svar.h): its local copies and
// the copy-in / copy-out of them, and the writer claims of its outputs.
//
// The data path reads nothing but what the set checked at creation: each
// variable's buffers as process-local pointers into the mapped table
// (validated by read_entry), so a value word changed in the file can at
// worst make a read retry, never move a copy outside the table.
//
// A set's writer claims name it by an id, unique in this process; the sets
// that live here are kept in g_sets by that id, so a claim of this process
// is live exactly while its set is (claim_live), and a task's end hook
// finds its sets by id even after one was destroyed (no dangling pointer).
#include <atomic>
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <new>

#include "chimera/bp.h"
#include "chimera/svar.h"
#include "chimera/task.h"
#include "ipc/backplane/stop_point.hpp"
#include "ipc/err/report.hpp"
#include "ipc/svar/svar.hpp"
#include "kernel/task/holds.hpp"
#include "lib/hot.hpp"

using namespace chm::ipc::svar;
namespace bp = chm::bp;

struct SetVar {
    Entry* e;              // the shared entry (its value words)
    char* buf0;            // its buffer 0 in this process
    void* local;           // the local copy
    std::uint32_t bytes, stride;
    char name[kNameLen];
};

struct chm_svar_set {
    std::uint32_t id;
    std::uint32_t token;   // a->token, at creation: what its claims name; read at every cycle (holds) without a's line
    bp::Attachment* a;
    std::uint32_t gen;     // the attachment's, at creation
    Table table;
    std::uint32_t n_in, n_out;
    std::size_t in_bytes, out_bytes;
    std::atomic<bool> claims_held;
    SetVar* vars;          // inputs, then outputs
    void* locals;          // one block for every local copy
    char owner[kNameLen];
};

namespace {

constexpr auto Acq = std::memory_order_acquire;
constexpr auto Rel = std::memory_order_release;
constexpr std::uint32_t kMaxSets = 1024;
constexpr std::uint32_t kIndexBits = 10;

std::atomic<chm_svar_set*> g_sets[kMaxSets];
std::atomic<std::uint32_t> g_serial{1};

// Put `s` in a free slot of g_sets; its id = serial << 10 | slot.
bool enlist(chm_svar_set* s) {
    const std::uint32_t serial = g_serial.fetch_add(1);
    for (std::uint32_t k = 0; k < kMaxSets; ++k) {
        const std::uint32_t i = (serial + k) % kMaxSets;
        chm_svar_set* expect = nullptr;
        s->id = (serial << kIndexBits) | i;
        if (s->id == 0) continue;
        if (g_sets[i].compare_exchange_strong(expect, s, Acq)) return true;
    }
    return false;
}

chm_svar_set* listed(std::uint32_t id) {
    chm_svar_set* s = g_sets[id % kMaxSets].load(Acq);
    return s && s->id == id ? s : nullptr;
}

void delist(chm_svar_set* s) {
    chm_svar_set* expect = s;
    g_sets[s->id % kMaxSets].compare_exchange_strong(expect, nullptr, Rel);
}

bool same_attachment(const chm_svar_set* s) {
    const bp::Attachment* a = bp::current();
    return a == s->a && a->gen == s->gen;
}

SetVar* outputs(chm_svar_set* s) { return s->vars + s->n_in; }

// Does entry `e` name `s` as its writer?
bool holds(const chm_svar_set* s, const Entry* e) {
    return e->writer_token.load(Acq) == s->token && e->writer_id.load(Acq) == s->id;
}

// Drop the set's claims (those still naming it) under the table lock.
int release_claims(chm_svar_set* s) {
    if (!s->claims_held.exchange(false)) return 0;
    if (!same_attachment(s)) return 0;  // left: the claims went with the slot
    if (int r = lock(s->table)) return r;
    for (std::uint32_t k = 0; k < s->n_out; ++k) {
        Entry* e = outputs(s)[k].e;
        if (holds(s, e)) {
            e->writer_token.store(0, Rel);
            e->writer_id.store(0, Rel);
        }
    }
    unlock(s->table);
    return 0;
}

void on_task_end(void* arg) {
    const auto id = std::uint32_t(reinterpret_cast<std::uintptr_t>(arg));
    if (chm_svar_set* s = listed(id)) release_claims(s);
}

void free_set(chm_svar_set* s) {
    std::free(s->locals);
    std::free(s->vars);
    s->~chm_svar_set();
    std::free(s);
}

bool duplicate(const char* const* names, std::size_t n, const char* const* more, std::size_t m, const char** which) {
    for (std::size_t i = 0; i < n + m; ++i) {
        const char* a = i < n ? names[i] : more[i - n];
        for (std::size_t j = i + 1; j < n + m; ++j) {
            const char* b = j < n ? names[j] : more[j - n];
            if (a && b && std::strcmp(a, b) == 0) return *which = a, true;
        }
    }
    return false;
}

// Resolve every name to a checked entry and lay out the local copies.
int resolve(chm_svar_set* s, const char* const* inputs, const char* const* outs) {
    const std::uint32_t n = s->n_in + s->n_out;
    EntryView* views = static_cast<EntryView*>(std::calloc(n ? n : 1, sizeof(EntryView)));
    if (!views) return bp::set_error("chm_svar_set_create %s: out of memory", s->owner), -ENOMEM;
    std::size_t total = 0;
    char why[300];
    int r = 0;
    for (std::uint32_t k = 0; k < n && r == 0; ++k) {
        const char* name = k < s->n_in ? inputs[k] : outs[k - s->n_in];
        if (!name) {
            r = -EINVAL;
            bp::set_error("chm_svar_set_create %s: NULL variable name", s->owner);
            break;
        }
        const int i = find(s->table, name, &views[k], why, sizeof why);
        if (i == -ENOENT) {
            r = i;
            bp::set_error("chm_svar_set_create %s: no state variable \"%s\"", s->owner, name);
        } else if (i < 0) {
            r = i;
            bp::set_error("chm_svar_set_create %s: %s", s->owner, why);
        }
        total += views[k].stride;
        (k < s->n_in ? s->in_bytes : s->out_bytes) += views[k].bytes;
    }
    if (r == 0 && n) {
        s->vars = static_cast<SetVar*>(std::calloc(n, sizeof(SetVar)));
        s->locals = std::aligned_alloc(16, total ? total : 16);
        if (!s->vars || !s->locals) r = -ENOMEM, bp::set_error("chm_svar_set_create %s: out of memory", s->owner);
    }
    std::size_t at = 0;
    for (std::uint32_t k = 0; k < n && r == 0; ++k) {
        SetVar& v = s->vars[k];
        v.e = s->table.entry(views[k].index);
        v.buf0 = s->table.base + views[k].buf;
        v.local = static_cast<char*>(s->locals) + at;
        v.bytes = views[k].bytes;
        v.stride = views[k].stride;
        std::memcpy(v.name, views[k].name, kNameLen);
        at += v.stride;
        std::memset(v.local, 0, v.stride);
        if (read_value_patient(v.e, v.buf0, v.stride, v.bytes, v.local)) {
            r = -EAGAIN;
            set_unsettled_error("chm_svar_set_create", s->owner, v.name);
        }
    }
    std::free(views);
    return r;
}

bool displaceable(const Entry* e, const char* const* displace, size_t n) {
    char other[kNameLen];
    std::memcpy(other, e->writer_name, kNameLen);
    other[kNameLen - 1] = 0;
    for (size_t i = 0; i < n; ++i)
        if (displace[i] && std::strncmp(displace[i], other, kNameLen) == 0) return true;
    return false;
}

// With the table lock held: could `s` claim every output now (each held by
// it, free, held by a dead writer or by one named in `displace`)? 0, or
// -EBUSY with the message naming the variable and its writer.
int check_claimable_locked(const chm_svar_set* s, const char* const* displace, size_t n_displace) {
    for (std::uint32_t k = 0; k < s->n_out; ++k) {
        const Entry* e = s->vars[s->n_in + k].e;
        if (holds(s, e) || !claim_live(s->table, e) || displaceable(e, displace, n_displace)) continue;
        char other[kNameLen];
        std::memcpy(other, e->writer_name, kNameLen);
        other[kNameLen - 1] = 0;
        bp::set_error("%s: state variable %s is written by %s already: one writer per variable", s->owner,
                      s->vars[s->n_in + k].name, other);
        return -EBUSY;
    }
    return 0;
}

// Claim every output for `s`, all or none, under the table lock; a live
// writer named in `displace` passes its claim on.
int claim_outputs(chm_svar_set* s, const char* const* displace, size_t n_displace, std::uint64_t since = 0,
                  DecisionRef sw = {}) {
    if (s->n_out == 0) return 0;
    if (int r = lock(s->table)) return r;
    if (int r = check_claimable_locked(s, displace, n_displace)) {
        unlock(s->table);
        return r;
    }
    bp::lock_mark_dirty(&s->table.hdr()->lock);
    for (std::uint32_t k = 0; k < s->n_out; ++k) {
        Entry* e = outputs(s)[k].e;
        if (holds(s, e)) continue;  // claiming again re-asserts only what another took
        std::memcpy(e->writer_name, s->owner, kNameLen);  // the name before the token: info reads both
        if (k == 0) CHM_STOP_POINT("svar.claim.locked");  // the first entry half written
        e->since_lo.store(std::uint32_t(since), Rel);
        e->since_hi.store(std::uint32_t(since >> 32), Rel);
        e->switch_cell.store(sw.none() ? 0 : sw.cell + 1, Rel);
        e->switch_seq.store(sw.seq, Rel);
        e->writer_id.store(s->id, Rel);
        e->writer_token.store(s->token, Rel);
    }
    bp::lock_clear_dirty(&s->table.hdr()->lock);
    s->claims_held.store(true);
    unlock(s->table);
    return 0;
}

// The argument checks every claim call makes, then `op` under the
// table lock (claim_outputs or check_claimable_locked); `call` names it.
template <class Op>
int with_claim_args(const char* call, chm_svar_set* set, const char* const* displace, size_t n_displace, Op op) {
    int r;
    if (!set || (n_displace && !displace)) r = (bp::set_error("%s: NULL set or names", call), -EINVAL);
    else if (!same_attachment(set))
        r = (bp::set_error("%s %s: its backplane attachment is gone", call, set->owner), -ENOTCONN);
    else r = op();
    return chm::ipc::leave(r, call);
}

int create_impl(const char* owner, const char* const* inputs, size_t n_in, const char* const* outs, size_t n_out,
                chm_svar_set_t** out, bool claim) {
    chm::kernel::CallScope in_call;  // a destroy or abort-cycle meanwhile waits for the return
    if (!out || !owner || !owner[0] || (n_in && !inputs) || (n_out && !outs))
        return bp::set_error("chm_svar_set_create: NULL or empty owner, NULL out or NULL name list"), -EINVAL;
    if (std::strlen(owner) > CHM_SVAR_NAME_MAX)
        return bp::set_error("chm_svar_set_create: owner \"%.40s...\" longer than %d", owner, CHM_SVAR_NAME_MAX),
               -ENAMETOOLONG;
    if (n_in + n_out > CHM_SVAR_CAPACITY)
        return bp::set_error("chm_svar_set_create %s: %zu variables, the table holds %d", owner, n_in + n_out,
                             CHM_SVAR_CAPACITY),
               -EINVAL;
    const char* dup = nullptr;
    if (duplicate(inputs, n_in, outs, n_out, &dup))
        return bp::set_error("chm_svar_set_create %s: %s is listed twice", owner, dup), -EINVAL;
    void* mem = std::calloc(1, sizeof(chm_svar_set));
    if (!mem) return bp::set_error("chm_svar_set_create %s: out of memory", owner), -ENOMEM;
    auto* s = new (mem) chm_svar_set{};
    std::strncpy(s->owner, owner, kNameLen - 1);
    s->n_in = std::uint32_t(n_in);
    s->n_out = std::uint32_t(n_out);
    int r = open_table(false, &s->table);
    if (r == -ENOENT) bp::set_error("chm_svar_set_create %s: no state variables are declared", owner);
    if (r == 0) {
        s->a = s->table.a;
        s->token = s->a->token;
        s->gen = s->table.gen;
        r = resolve(s, inputs, outs);
    }
    if (r == 0 && !enlist(s)) r = -ENOMEM, bp::set_error("chm_svar_set_create %s: %u sets live in this process", owner, kMaxSets);
    if (r == 0 && claim && (r = claim_outputs(s, nullptr, 0))) {
        delist(s);
        char why[400];
        std::snprintf(why, sizeof why, "%s", chm_bp_last_error());
        bp::set_error("chm_svar_set_create %s", why);
    }
    if (r) {
        free_set(s);
        return r;
    }
    // Inside a task, its claims end with it, however it ends.
    if (chm_task_self() != CHM_TID_NONE)
        (void)chm_task_on_end(on_task_end, reinterpret_cast<void*>(std::uintptr_t(s->id)));
    *out = s;
    return 0;
}

CHM_HOT int read_impl(chm_svar_set* s) {
    int r = 0;
    for (std::uint32_t k = 0; k < s->n_in; ++k) {
        const SetVar& v = s->vars[k];
        if (read_value(v.e, v.buf0, v.stride, v.bytes, v.local) != 0 && r == 0) {
            r = -EAGAIN;
            bp::set_error("chm_svar_set_read %s: %s changed under %u reads in a row", s->owner, v.name, kReadAttempts);
        }
    }
    return r;
}

}  // namespace

bool chm::ipc::svar::set_alive(std::uint32_t id) {
    const chm_svar_set* s = listed(id);
    return s && s->claims_held.load(Acq);
}

namespace chm::ipc::svar {

const Table& set_table(const chm_svar_set* s) { return s->table; }

int set_claim_for_switch(chm_svar_set* s, const char* const* displace, std::size_t n_displace, std::uint64_t since,
                         DecisionRef r) {
    return claim_outputs(s, displace, n_displace, since, r);
}

CHM_HOT int set_displaced_by(const chm_svar_set* s, std::uint64_t release, DecisionRef* by) {
    if (!s->claims_held.load(std::memory_order_relaxed)) return 0;
    for (std::uint32_t k = 0; k < s->n_out; ++k) {
        const Entry* e = s->vars[s->n_in + k].e;
        if (holds(s, e)) continue;
        // Taken: by whom, since when and on which switch's decision is
        // written before the token.
        const std::uint64_t since = std::uint64_t(e->since_hi.load(Acq)) << 32 | e->since_lo.load(Acq);
        if (since > release) continue;
        const std::uint32_t cell = e->switch_cell.load(Acq);
        *by = cell ? DecisionRef{cell - 1, e->switch_seq.load(Acq)} : DecisionRef{};
        return 1;
    }
    return 0;
}

CHM_HOT int set_copy_in(chm_svar_set* s) { return read_impl(s); }

CHM_HOT int set_copy_out(chm_svar_set* s) {
    if (s->n_out && !s->claims_held.load(std::memory_order_relaxed)) return -EPERM;
    for (std::uint32_t k = 0; k < s->n_out; ++k) {
        SetVar& v = s->vars[s->n_in + k];
        write_value(v.e, v.buf0, v.stride, v.bytes, v.local);
    }
    return 0;
}

int set_reclaim_after_abort(chm_svar_set* s, DecisionRef r) {
    if (s->n_out == 0) return 0;
    if (int err = lock(s->table)) return err;
    bp::lock_mark_dirty(&s->table.hdr()->lock);
    for (std::uint32_t k = 0; k < s->n_out; ++k) {
        Entry* e = outputs(s)[k].e;
        if (holds(s, e)) continue;
        const bool by_r = e->switch_cell.load(Acq) == r.cell + 1 && e->switch_seq.load(Acq) == r.seq;
        if (!by_r && claim_live(s->table, e)) continue;  // another writer's, by a later claim: not ours to take
        std::memcpy(e->writer_name, s->owner, kNameLen);
        e->since_lo.store(0, Rel);
        e->since_hi.store(0, Rel);
        e->switch_cell.store(0, Rel);
        e->switch_seq.store(0, Rel);
        e->writer_id.store(s->id, Rel);
        e->writer_token.store(s->token, Rel);
    }
    bp::lock_clear_dirty(&s->table.hdr()->lock);
    s->claims_held.store(true);
    unlock(s->table);
    return 0;
}

}  // namespace chm::ipc::svar

extern "C" {

int chm_svar_set_create(const char* owner, const char* const* inputs, size_t n_in, const char* const* outputs,
                        size_t n_out, chm_svar_set_t** out) {
    return chm::ipc::leave(create_impl(owner, inputs, n_in, outputs, n_out, out, true), "chm_svar_set_create");
}

int chm_svar_set_open(const char* owner, const char* const* inputs, size_t n_in, const char* const* outputs,
                      size_t n_out, chm_svar_set_t** out) {
    return chm::ipc::leave(create_impl(owner, inputs, n_in, outputs, n_out, out, false), "chm_svar_set_open");
}

int chm_svar_set_claim(chm_svar_set_t* set, const char* const* displace, size_t n_displace) {
    chm::kernel::CallScope in_call;  // a destroy or abort-cycle meanwhile waits for the return
    return with_claim_args("chm_svar_set_claim", set, displace, n_displace,
                           [&] { return claim_outputs(set, displace, n_displace); });
}

int chm_svar_set_claim_at(chm_svar_set_t* set, const char* const* displace, size_t n_displace, uint64_t at_ns) {
    chm::kernel::CallScope in_call;  // a destroy or abort-cycle meanwhile waits for the return
    return with_claim_args("chm_svar_set_claim_at", set, displace, n_displace,
                           [&] { return claim_outputs(set, displace, n_displace, at_ns); });
}

int chm_svar_set_check_claim(chm_svar_set_t* set, const char* const* displace, size_t n_displace) {
    chm::kernel::CallScope in_call;  // a destroy or abort-cycle meanwhile waits for the return
    return with_claim_args("chm_svar_set_check_claim", set, displace, n_displace, [&] {
        int r = lock(set->table);
        if (r == 0) {
            r = check_claimable_locked(set, displace, n_displace);
            unlock(set->table);
        }
        return r;
    });
}

int chm_svar_set_displaced(const chm_svar_set_t* set, uint64_t release_ns) {
    if (!set || !set->claims_held.load(std::memory_order_relaxed)) return 0;
    for (std::uint32_t k = 0; k < set->n_out; ++k) {
        const Entry* e = set->vars[set->n_in + k].e;
        if (holds(set, e)) continue;
        // Taken: by whom and since when is written before the token.
        const std::uint64_t since = std::uint64_t(e->since_hi.load(Acq)) << 32 | e->since_lo.load(Acq);
        if (since <= release_ns) return 1;
    }
    return 0;
}

int chm_svar_set_release(chm_svar_set_t* set) {
    chm::kernel::CallScope in_call;  // a destroy or abort-cycle meanwhile waits for the return
    if (!set) return chm::ipc::leave((bp::set_error("chm_svar_set_release: NULL set"), -EINVAL), "chm_svar_set_release");
    return chm::ipc::leave(release_claims(set), "chm_svar_set_release");
}

void* chm_svar_set_local(const chm_svar_set_t* set, const char* name) {
    if (!set || !name) return nullptr;
    for (std::uint32_t k = 0; k < set->n_in + set->n_out; ++k)
        if (std::strncmp(set->vars[k].name, name, kNameLen) == 0) return set->vars[k].local;
    return nullptr;
}

int chm_svar_set_read(chm_svar_set_t* set) {
    if (!set) return chm::ipc::leave((bp::set_error("chm_svar_set_read: NULL set"), -EINVAL), "chm_svar_set_read");
    if (!same_attachment(set))
        return chm::ipc::leave((bp::set_error("chm_svar_set_read %s: its backplane attachment is gone", set->owner),
                                -ENOTCONN),
                               "chm_svar_set_read");
    return chm::ipc::leave(read_impl(set), "chm_svar_set_read");
}

int chm_svar_set_write(chm_svar_set_t* set) {
    if (!set) return chm::ipc::leave((bp::set_error("chm_svar_set_write: NULL set"), -EINVAL), "chm_svar_set_write");
    if (!same_attachment(set))
        return chm::ipc::leave((bp::set_error("chm_svar_set_write %s: its backplane attachment is gone", set->owner),
                                -ENOTCONN),
                               "chm_svar_set_write");
    if (chm::ipc::svar::set_copy_out(set) == -EPERM)
        return chm::ipc::leave((bp::set_error("chm_svar_set_write %s: the set holds no claim on its outputs", set->owner),
                                -EPERM),
                               "chm_svar_set_write");
    return 0;
}

int chm_svar_set_bytes(const chm_svar_set_t* set, size_t* in_bytes, size_t* out_bytes) {
    if (!set) return chm::ipc::leave((bp::set_error("chm_svar_set_bytes: NULL set"), -EINVAL), "chm_svar_set_bytes");
    if (in_bytes) *in_bytes = set->in_bytes;
    if (out_bytes) *out_bytes = set->out_bytes;
    return 0;
}

int chm_svar_set_destroy(chm_svar_set_t* set) {
    chm::kernel::CallScope in_call;  // a destroy or abort-cycle meanwhile waits for the return
    if (!set)
        return chm::ipc::leave((bp::set_error("chm_svar_set_destroy: NULL set"), -EINVAL), "chm_svar_set_destroy");
    const int r = release_claims(set);
    delist(set);
    free_set(set);
    return chm::ipc::leave(r, "chm_svar_set_destroy");
}

}  // extern "C"
