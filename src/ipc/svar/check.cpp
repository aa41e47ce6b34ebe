// The state-variable table's part of the backplane's checks: its
// validator (chm_bp_validate, chimera start and status), its strict check
// (chimera-bpcheck) and its recovery after a death (the table lock robbed,
// a half-made declaration dropped, the dead process's writer claims
// cleared so the variables can be written again at once).
#include <atomic>
#include <cstdio>

#include "ipc/svar/svar.hpp"

namespace chm::ipc {

namespace {
constexpr auto R = std::memory_order_relaxed;

svar::Table view_table(const bp::View& v, std::uint32_t off, std::uint32_t size) {
    svar::Table t;
    t.base = v.base + off;
    t.size = size;
    const auto* h = t.hdr();
    t.capacity = h->capacity;
    t.data_offset = h->data_offset;
    t.data_size = h->data_size;
    return t;
}

// Header and every published entry. 0 or kCorrupt + why.
int validate_all(const bp::View& v, std::uint32_t off, std::uint32_t size, char* why, std::size_t n) {
    if (int r = svar::validate_header(v.base + off, size, why, n)) return r;
    const svar::Table t = view_table(v, off, size);
    std::uint32_t count;
    if (int r = svar::published(t, &count, why, n)) return r;
    for (std::uint32_t i = 0; i < count; ++i) {
        svar::EntryView e;
        if (int r = svar::read_entry(t, i, &e, why, n)) return r;
    }
    const std::uint32_t used = t.hdr()->data_used.load(R);
    if (used > t.data_size)
        return bp::corrupt(why, n, "state-variable table: data_used %u above its %u bytes", used, t.data_size);
    return 0;
}
}  // namespace

int svar_validate(const bp::View& v, std::uint32_t off, std::uint32_t size, const char* name, char* why,
                  std::size_t n) {
    char inner[300];
    if (validate_all(v, off, size, inner, sizeof inner) == 0) return 0;
    return bp::corrupt(why, n, "%s: %s", name, inner);
}

void svar_check(const bp::View& v, std::uint32_t off, std::uint32_t size, const char* name, bp::Report& r) {
    char why[300];
    if (validate_all(v, off, size, why, sizeof why)) {
        r.problem("%s: %s", name, why);
        return;
    }
    const svar::Table t = view_table(v, off, size);
    char what[96];
    std::snprintf(what, sizeof what, "%s lock", name);
    bp::check_lock(v, t.hdr()->lock, what, r);
}

void svar_recover(const bp::View& v, std::uint32_t index, std::uint32_t dead_slot, std::uint32_t dead_gen,
                  std::uint32_t rt) {
    std::uint32_t off, size;
    char why[300];
    if (bp::entry_payload(v, index, svar::kTableBytesMin, &off, &size, why, sizeof why) != 0) return;
    if (validate_all(v, off, size, why, sizeof why) != 0) return;  // corrupt: opens refuse it anyway
    const svar::Table t = view_table(v, off, size);
    bp::Lock* l = &t.hdr()->lock;
    if (bp::lock_acquire_recovery(v, l, rt) == -ETIMEDOUT) return;
    const std::uint32_t dead = bp::make_token(dead_slot, dead_gen);
    std::uint32_t count;
    if (svar::published(t, &count, why, sizeof why) == 0) {
        if (l->dirty.load(R)) svar::repair_locked(t);
        for (std::uint32_t i = 0; i < count; ++i) {
            svar::Entry* e = t.entry(i);
            if (e->writer_token.load(R) != dead) continue;
            e->writer_token.store(0);
            e->writer_id.store(0);
        }
    }
    bp::lock_clear_dirty(l);
    bp::lock_release(l);
}

}  // namespace chm::ipc
