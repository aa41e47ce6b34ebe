// The table calls of chimera/svar.h: declare, info, count, get. Sets are
// in set.cpp. Every call leaves through ipc::leave (module "ipc" errors).
#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>

#include "chimera/svar.h"
#include "ipc/err/report.hpp"
#include "ipc/svar/svar.hpp"
#include "kernel/task/holds.hpp"

using namespace chm::ipc::svar;
namespace bp = chm::bp;

namespace {

constexpr auto R = std::memory_order_relaxed;
constexpr auto Rel = std::memory_order_release;

const char* type_name(std::uint32_t t) {
    switch (t) {
    case CHM_SVAR_DOUBLE: return "double";
    case CHM_SVAR_FLOAT: return "float";
    case CHM_SVAR_INT32: return "int32";
    case CHM_SVAR_UINT32: return "uint32";
    case CHM_SVAR_BOOL: return "bool";
    default: return "?";
    }
}

// A C caller may store any int in an enum field: read it as the integer it
// is (loading an out-of-range enum is undefined in C++).
std::uint32_t raw_type(const chm_svar_decl_t* d) {
    static_assert(sizeof d->type == sizeof(std::uint32_t));
    std::uint32_t v;
    std::memcpy(&v, &d->type, sizeof v);
    return v;
}

int check_decl(const chm_svar_decl_t* d) {
    if (!d || !d->name || !d->name[0])
        return bp::set_error("chm_svar_declare: NULL declaration or empty name"), -EINVAL;
    if (std::strlen(d->name) > CHM_SVAR_NAME_MAX)
        return bp::set_error("chm_svar_declare: name \"%.40s...\" longer than %d", d->name, CHM_SVAR_NAME_MAX),
               -ENAMETOOLONG;
    if (d->unit && std::strlen(d->unit) > CHM_SVAR_UNIT_MAX)
        return bp::set_error("chm_svar_declare %s: unit longer than %d", d->name, CHM_SVAR_UNIT_MAX), -ENAMETOOLONG;
    if (!elem_size(raw_type(d)))
        return bp::set_error("chm_svar_declare %s: unknown type %u", d->name, raw_type(d)), -EINVAL;
    if (d->rows == 0 || d->cols == 0 || std::uint64_t(d->rows) * d->cols > kElemsMax)
        return bp::set_error("chm_svar_declare %s: shape %ux%u (1..%u elements)", d->name, d->rows, d->cols,
                             kElemsMax),
               -EINVAL;
    return 0;
}

int declare_locked(const Table& t, const chm_svar_decl_t* d) {
    char why[300];
    const char* unit = d->unit ? d->unit : "";
    EntryView v;
    const int i = find(t, d->name, &v, why, sizeof why);
    if (i == bp::kCorrupt) return bp::set_error("chm_svar_declare %s: %s", d->name, why), i;
    if (i >= 0) {
        if (v.type == std::uint32_t(d->type) && v.rows == d->rows && v.cols == d->cols && !std::strcmp(v.unit, unit))
            return 0;
        bp::set_error("chm_svar_declare: %s is declared as %s %ux%u [%s]; this declaration says %s %ux%u [%s]", d->name,
                      type_name(v.type), v.rows, v.cols, v.unit, type_name(d->type), d->rows, d->cols, unit);
        return -EEXIST;
    }
    TableHeader* h = t.hdr();
    const std::uint32_t count = h->count.load(R);
    if (count >= t.capacity)
        return bp::set_error("chm_svar_declare %s: the table is full (%u variables)", d->name, t.capacity), -ENOSPC;
    const std::uint32_t bytes = d->rows * d->cols * elem_size(d->type);
    const std::uint32_t stride = round16(bytes);
    const std::uint32_t used = h->data_used.load(R);
    if (used > t.data_size || 2ull * stride > t.data_size - used)
        return bp::set_error("chm_svar_declare %s: %u bytes of values needed, %u of %u free", d->name, 2 * stride,
                             used > t.data_size ? 0 : t.data_size - used, t.data_size),
               -ENOSPC;
    bp::lock_mark_dirty(&h->lock);
    Entry* e = t.entry(count);
    e->type = d->type;
    e->rows = d->rows;
    e->cols = d->cols;
    e->bytes = bytes;
    e->stride = stride;
    e->buf = t.data_offset + used;
    std::memset(t.base + e->buf, 0, 2 * stride);
    e->latest.store(0, R);  // value 0 is in buffer 0, complete
    e->bseq[0].store(2, R);
    e->bseq[1].store(0, R);
    e->writer_token.store(0, R);
    e->writer_id.store(0, R);
    e->since_lo.store(0, R);
    e->since_hi.store(0, R);
    std::memset(e->name, 0, kNameLen);
    std::memcpy(e->name, d->name, std::strlen(d->name));
    std::memset(e->unit, 0, kUnitLen);
    std::memcpy(e->unit, unit, std::strlen(unit));
    std::memset(e->writer_name, 0, kNameLen);
    e->state.store(kEntryLive, Rel);
    h->data_used.store(used + 2 * stride, Rel);
    h->count.store(count + 1, Rel);  // published
    bp::lock_clear_dirty(&h->lock);
    return 0;
}

int declare_impl(const chm_svar_decl_t* d) {
    chm::kernel::CallScope in_call;  // a destroy or abort-cycle meanwhile waits for the return
    if (int r = check_decl(d)) return r;
    Table t;
    if (int r = open_table(true, &t)) return r;
    if (int r = lock(t)) return r;
    const int r = declare_locked(t, d);
    unlock(t);
    return r;
}

void fill_info(const Table& t, const EntryView& v, chm_svar_info_t* out) {
    std::memset(out, 0, sizeof *out);
    std::memcpy(out->name, v.name, sizeof out->name);
    out->type = chm_svar_type_t(v.type);
    out->rows = v.rows;
    out->cols = v.cols;
    std::memcpy(out->unit, v.unit, sizeof out->unit);
    out->bytes = v.bytes;
    const Entry* e = t.entry(v.index);
    out->writes = e->latest.load(R);
    // Under the table lock, the writer's name and its claim agree.
    if (lock(t) == 0) {
        out->has_writer = claim_live(t, e);
        if (out->has_writer) {
            std::memcpy(out->writer, e->writer_name, sizeof out->writer);
            out->writer[sizeof out->writer - 1] = 0;
        }
        unlock(t);
    }
}

int info_impl(const char* name, chm_svar_info_t* out) {
    if (!name || !out) return bp::set_error("chm_svar_info: NULL name or out"), -EINVAL;
    Table t;
    if (int r = open_table(false, &t)) return r;
    char why[300];
    EntryView v;
    const int i = find(t, name, &v, why, sizeof why);
    if (i == -ENOENT) return bp::set_error("chm_svar_info: no state variable \"%s\"", name), i;
    if (i < 0) return bp::set_error("chm_svar_info %s: %s", name, why), i;
    fill_info(t, v, out);
    return 0;
}

int count_impl() {
    Table t;
    const int r = open_table(false, &t);
    if (r == -ENOENT) return 0;  // nothing declared yet
    if (r) return r;
    std::uint32_t count;
    char why[200];
    if (int c = published(t, &count, why, sizeof why)) return bp::set_error("chm_svar_count: %s", why), c;
    return int(count);
}

int info_at_impl(int index, chm_svar_info_t* out) {
    if (!out) return bp::set_error("chm_svar_info_at: NULL out"), -EINVAL;
    Table t;
    if (int r = open_table(false, &t)) return r == -ENOENT ? (bp::set_error("chm_svar_info_at: no variables"), r) : r;
    std::uint32_t count;
    char why[300];
    if (int r = published(t, &count, why, sizeof why)) return bp::set_error("chm_svar_info_at: %s", why), r;
    if (index < 0 || std::uint32_t(index) >= count)
        return bp::set_error("chm_svar_info_at: no variable %d (%u declared)", index, count), -ENOENT;
    EntryView v;
    if (int r = read_entry(t, std::uint32_t(index), &v, why, sizeof why))
        return bp::set_error("chm_svar_info_at: %s", why), r;
    fill_info(t, v, out);
    return 0;
}

int get_impl(const char* name, void* buf, size_t size) {
    if (!name || !buf) return bp::set_error("chm_svar_get: NULL name or buffer"), -EINVAL;
    Table t;
    if (int r = open_table(false, &t)) return r;
    char why[300];
    EntryView v;
    const int i = find(t, name, &v, why, sizeof why);
    if (i == -ENOENT) return bp::set_error("chm_svar_get: no state variable \"%s\"", name), i;
    if (i < 0) return bp::set_error("chm_svar_get %s: %s", name, why), i;
    if (size < v.bytes) return bp::set_error("chm_svar_get %s: %zu bytes given, the value has %u", name, size, v.bytes), -EMSGSIZE;
    if (read_value_patient(t.entry(v.index), t.base + v.buf, v.stride, v.bytes, buf))
        return set_unsettled_error("chm_svar_get", name, "the value"), -EAGAIN;
    return 0;
}

}  // namespace

extern "C" {

int chm_svar_declare(const chm_svar_decl_t* decl) {
    return chm::ipc::leave(declare_impl(decl), "chm_svar_declare");
}
int chm_svar_info(const char* name, chm_svar_info_t* out) {
    return chm::ipc::leave(info_impl(name, out), "chm_svar_info");
}
int chm_svar_count(void) { return chm::ipc::leave(count_impl(), "chm_svar_count"); }
int chm_svar_info_at(int index, chm_svar_info_t* out) {
    return chm::ipc::leave(info_at_impl(index, out), "chm_svar_info_at");
}
int chm_svar_get(const char* name, void* buf, size_t size) {
    return chm::ipc::leave(get_impl(name, buf, size), "chm_svar_get");
}

}  // extern "C"
