// The global state-variable table: finding or creating it, checking what
// the file says of it before believing it, declaring variables, and the
// double-buffered value path (svar.hpp says why double buffers).
#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>

#include "chimera/svar.h"
#include "ipc/svar/svar.hpp"
#include "kernel/task/holds.hpp"
#include "lib/hot.hpp"
#include "port.hpp"

namespace chm::ipc::svar {

namespace {
constexpr auto R = std::memory_order_relaxed;
constexpr auto Acq = std::memory_order_acquire;
constexpr auto Rel = std::memory_order_release;

// A fixed-size text field of the file, NUL-terminated within its bytes?
bool terminated(const char* s, std::size_t n) { return ::memchr(s, 0, n) != nullptr; }

int init_table(char* base, std::uint32_t size, std::uint32_t capacity) {
    auto* h = reinterpret_cast<TableHeader*>(base);
    std::memset(base, 0, size);
    h->capacity = capacity;
    h->data_offset = round16(std::uint32_t(cells_offset(capacity) + kDecisionCells * sizeof(Cell)));
    h->data_size = (size - h->data_offset) & ~15u;
    h->version = kTableVersion;
    std::atomic_thread_fence(Rel);
    h->magic = kTableMagic;
    return 0;
}

// The table's size for this backplane: the default, or half of common
// memory on a small backplane (a test's or a board's), so a declaration
// never fails only because the defaults are sized for a workstation.
std::uint32_t table_bytes(const bp::View& v, std::uint32_t* capacity) {
    const std::uint32_t half = (v.geo().common_size / 2) & ~4095u;
    std::uint32_t data = std::min<std::uint32_t>(CHM_SVAR_DATA_BYTES, half);
    *capacity = CHM_SVAR_CAPACITY;
    const std::uint32_t entries = round16(std::uint32_t(cells_offset(*capacity) + kDecisionCells * sizeof(Cell)));
    if (data < entries + 4096) data = entries + 4096;  // at least a page of values
    return entries + data;
}
}  // namespace

std::uint32_t elem_size(std::uint32_t type) {
    switch (type) {
    case CHM_SVAR_DOUBLE: return 8;
    case CHM_SVAR_FLOAT:
    case CHM_SVAR_INT32:
    case CHM_SVAR_UINT32: return 4;
    case CHM_SVAR_BOOL: return 1;
    default: return 0;
    }
}

int validate_header(const char* base, std::uint32_t size, char* why, std::size_t n) {
    const auto* h = reinterpret_cast<const TableHeader*>(base);
    if (size < kTableBytesMin) return bp::corrupt(why, n, "state-variable table: %u bytes, too small", size);
    if (h->magic != kTableMagic) return bp::corrupt(why, n, "state-variable table: magic 0x%08x", h->magic);
    if (h->version != kTableVersion)
        return bp::corrupt(why, n, "state-variable table: version %u, this build reads %u", h->version, kTableVersion);
    const std::uint64_t entries_end = cells_offset(h->capacity) + kDecisionCells * sizeof(Cell);
    if (h->capacity == 0 || entries_end > size)
        return bp::corrupt(why, n, "state-variable table: capacity %u does not fit in %u bytes", h->capacity, size);
    if (h->data_offset < entries_end || h->data_offset % 16 || h->data_offset > size ||
        h->data_size > size - h->data_offset)
        return bp::corrupt(why, n, "state-variable table: data area %u+%u outside %llu..%u", h->data_offset,
                           h->data_size, (unsigned long long)entries_end, size);
    return 0;
}

int published(const Table& t, std::uint32_t* count, char* why, std::size_t n) {
    *count = t.hdr()->count.load(Acq);
    if (*count > t.capacity)
        return bp::corrupt(why, n, "state-variable table: count %u above capacity %u", *count, t.capacity);
    return 0;
}

int read_entry(const Table& t, std::uint32_t i, EntryView* out, char* why, std::size_t n) {
    const Entry* e = t.entry(i);
    if (e->state.load(Acq) != kEntryLive)
        return bp::corrupt(why, n, "state variable [%u]: state %u in the published range", i, e->state.load(R));
    EntryView v;
    v.index = i;
    v.type = e->type;
    v.rows = e->rows;
    v.cols = e->cols;
    v.bytes = e->bytes;
    v.stride = e->stride;
    v.buf = e->buf;
    std::memcpy(v.name, e->name, kNameLen);
    std::memcpy(v.unit, e->unit, kUnitLen);
    if (!terminated(v.name, kNameLen) || !v.name[0])
        return bp::corrupt(why, n, "state variable [%u]: name not terminated or empty", i);
    if (!terminated(v.unit, kUnitLen)) return bp::corrupt(why, n, "state variable [%u] %s: unit not terminated", i, v.name);
    const std::uint32_t es = elem_size(v.type);
    if (!es) return bp::corrupt(why, n, "state variable [%u] %s: type %u", i, v.name, v.type);
    if (v.rows == 0 || v.cols == 0 || std::uint64_t(v.rows) * v.cols > kElemsMax)
        return bp::corrupt(why, n, "state variable [%u] %s: shape %ux%u", i, v.name, v.rows, v.cols);
    if (v.bytes != v.rows * v.cols * es || v.stride != round16(v.bytes))
        return bp::corrupt(why, n, "state variable [%u] %s: bytes %u / stride %u for %ux%u of %u", i, v.name, v.bytes,
                           v.stride, v.rows, v.cols, es);
    if (v.buf % 16 || v.buf < t.data_offset ||
        std::uint64_t(v.buf) + 2ull * v.stride > std::uint64_t(t.data_offset) + t.data_size)
        return bp::corrupt(why, n, "state variable [%u] %s: buffer %u+2x%u outside the data area %u+%u", i, v.name,
                           v.buf, v.stride, t.data_offset, t.data_size);
    *out = v;
    return 0;
}

int find(const Table& t, const char* name, EntryView* out, char* why, std::size_t n) {
    std::uint32_t count;
    if (int r = published(t, &count, why, n)) return r;
    for (std::uint32_t i = 0; i < count; ++i) {
        // Names are immutable once published: compare before validating all.
        if (std::strncmp(t.entry(i)->name, name, kNameLen) != 0) continue;
        if (int r = read_entry(t, i, out, why, n)) return r;
        return int(i);
    }
    return -ENOENT;
}

int open_table(bool create, Table* out) {
    bp::Attachment* a = bp::need_attachment();
    if (!a) return -ENOTCONN;
    bp::EntryInfo info{};
    int r = bp::registry_lookup(*a, kTableName, bp::kKindStateVars, &info);
    if (r == -ENOENT && create) {
        if ((r = bp::registry_lock(*a, a->token))) {
            bp::set_error("backplane %s: registry lock: a live holder kept it past the bound", a->path);
            return r;
        }
        const int found = bp::registry_find_locked(*a, kTableName, bp::kKindStateVars);
        if (found >= 0) {
            r = bp::registry_lookup(*a, kTableName, bp::kKindStateVars, &info);
        } else {
            std::uint32_t capacity;
            const std::uint32_t bytes = table_bytes(*a, &capacity);
            r = bp::registry_create_locked(*a, a->token, bp::kKindStateVars, kTableName, bytes, bp::kWhereCommon,
                                           a->slot, &info);
            if (r == 0) init_table(a->base + info.offset, bytes, capacity);
        }
        bp::registry_unlock(*a);
        switch (r) {
        case 0: break;
        case -EEXIST: bp::set_error("the name \"%s\" is taken by another kind of object", kTableName); return r;
        case -ENOMEM: bp::set_error("no room in common memory for the state-variable table"); return r;
        case -ENOSPC: bp::set_error("the registry is full: no entry for the state-variable table"); return r;
        default: bp::set_error("cannot create the state-variable table: error %d", r); return r;
        }
    }
    if (r == -ENOENT) {
        bp::set_error("no state-variable table on this backplane (nothing declared yet)");
        return r;
    }
    char why[300];
    std::uint32_t off, size;
    r = bp::entry_payload(*a, info.index, kTableBytesMin, &off, &size, why, sizeof why);
    if (r == 0) r = validate_header(a->base + off, size, why, sizeof why);
    if (r) {
        bp::set_error("backplane %s: %s", a->path, why);
        return r;
    }
    const auto* h = reinterpret_cast<const TableHeader*>(a->base + off);
    out->a = a;
    out->gen = a->gen;
    out->base = a->base + off;
    out->size = size;
    out->capacity = h->capacity;
    out->data_offset = h->data_offset;
    out->data_size = h->data_size;
    return 0;
}

void repair_locked(const Table& t) {
    std::uint32_t count;
    char why[200];
    if (published(t, &count, why, sizeof why)) count = 0;
    std::uint32_t used = 0;
    for (std::uint32_t i = 0; i < count; ++i) {
        EntryView v;
        if (read_entry(t, i, &v, why, sizeof why) == 0)
            used = std::max(used, v.buf + 2 * v.stride - t.data_offset);
    }
    if (count < t.capacity) t.entry(count)->state.store(kEntryFree, Rel);
    t.hdr()->data_used.store(used, Rel);
}

// Every locked stretch of the table is a call scope (kernel/task/holds.hpp):
// a destroy or abort-cycle of the task meanwhile is owed until unlock, so
// the change the lock guards is finished, not left to the repair.
int lock(const Table& t) {
    bp::Lock* l = &t.hdr()->lock;
    kernel::call_enter();
    const int r = bp::lock_acquire(*t.a, l, t.a->token, bp::kInternalPollNs, bp::kInternalTimeoutNs);
    if (r == -ETIMEDOUT) {
        kernel::call_leave();
        bp::set_error("state-variable table: a live holder kept its lock past 5 s");
        return r;
    }
    if (r == -EOWNERDEAD || l->dirty.load(R)) {
        repair_locked(t);
        bp::lock_clear_dirty(l);
    }
    return 0;
}

void unlock(const Table& t) {
    bp::lock_release(&t.hdr()->lock);
    kernel::call_leave();  // what was owed meanwhile happens here
}

CHM_HOT int read_value(const Entry* e, const char* buf0, std::uint32_t stride, std::uint32_t bytes, void* dst) {
    for (unsigned attempt = 0; attempt < kReadAttempts; ++attempt) {
        const std::uint32_t n = e->latest.load(Acq);
        const std::uint32_t b = n & 1;
        const std::uint32_t want = 2 * n + 2;
        if (e->bseq[b].load(Acq) != want) continue;  // lapped: write n+1 is already in
        std::memcpy(dst, buf0 + b * stride, bytes);
        std::atomic_thread_fence(Acq);
        if (e->bseq[b].load(R) == want) return 0;
    }
    return -EAGAIN;
}

int read_value_patient(const Entry* e, const char* buf0, std::uint32_t stride, std::uint32_t bytes, void* dst) {
    if (read_value(e, buf0, stride, bytes, dst) == 0) return 0;
    const std::uint64_t end = port::now_ns() + kPatientReadNs;
    do {
        if (read_value(e, buf0, stride, bytes, dst) == 0) return 0;
    } while (port::now_ns() < end);
    return -EAGAIN;
}

void set_unsettled_error(const char* fn, const char* owner, const char* what) {
    bp::set_error("%s %s: %s changed under every read for %llu ms (a corrupt sequence word, or a writer that laps "
                  "every copy)", fn, owner, what, static_cast<unsigned long long>(kPatientReadNs / 1'000'000));
}

CHM_HOT void write_value(Entry* e, char* buf0, std::uint32_t stride, std::uint32_t bytes, const void* src) {
    const std::uint32_t n = e->latest.load(R) + 1;  // the one writer: nobody else moves it
    const std::uint32_t b = n & 1;
    e->bseq[b].store(2 * n + 1, R);
    std::atomic_thread_fence(Rel);  // the odd mark before any byte of the copy
    std::memcpy(buf0 + b * stride, src, bytes);
    e->bseq[b].store(2 * n + 2, Rel);
    e->latest.store(n, Rel);
}

bool claim_live(const Table& t, const Entry* e) {
    const std::uint32_t tok = e->writer_token.load(Acq);
    if (tok == 0) return false;
    if (tok == t.a->token) return set_alive(e->writer_id.load(R));
    return bp::token_alive(*t.a, tok, true);
}

}  // namespace chm::ipc::svar
