// The global state-variable table (include/chimera/svar.h): its layout in
// the backplane and the internal interface of table.cpp and set.cpp.
//
// The table is one registry object of kind kKindStateVars named
// kTableName, in common memory, created by the first declaration:
//
//   TableHeader | Entry[capacity] | Cell[kDecisionCells] | value buffers
//
// The decision cells belong to servo switches (one per switch under way,
// see "Decision cells" below).
//
// Entries are appended under the table lock and never removed: entry i is
// published by count becoming > i (release), and from then on only its
// value words (latest, bseq) and its writer claim change. Each variable
// has two buffers of `stride` bytes. Write number n (n = 1, 2, ...) goes
// into buffer n & 1 while bseq[n & 1] = 2n+1, then bseq = 2n+2 and
// latest = n. A reader copies buffer latest & 1 and keeps the copy if that
// buffer's bseq was 2*latest+2 before and after: a writer preempted or
// dead mid-write never holds a reader up (it writes the other buffer), and
// a reader retries only when two writes landed during its copy.
//
// Why double buffers rather than one seqlock per variable: with one
// buffer, every reader on every RTPU spins while the writer's task is
// preempted in the middle of its copy-out (for as long as its RTPU runs a
// more urgent task), and for ever when it died there. The second buffer
// costs memory, never time: one memcpy per read and per write, as before.
#pragma once

#include <cstddef>
#include <cstdint>

#include "ipc/backplane/backplane.hpp"

struct chm_svar_set;  // set.cpp (chimera/svar.h: chm_svar_set_t)

namespace chm::ipc::svar {

using bp::A32;

inline constexpr char kTableName[] = "chimera.svar";
inline constexpr std::uint32_t kTableMagic = 0x53564152;  // "SVAR"
inline constexpr std::uint32_t kTableVersion = 3;  // 2: the claim's hand-over instant; 3: decision cells
inline constexpr std::uint32_t kNameLen = 32;  // name and writer name, NUL included
inline constexpr std::uint32_t kUnitLen = 16;
inline constexpr std::uint32_t kElemsMax = 65536;
inline constexpr unsigned kReadAttempts = 64;
// How long a call that must return a value (a set's first copy,
// chm_svar_get) goes on trying when its writer laps every attempt: a
// writer that never pauses can lap a reader whose copy is slower than two
// of its writes many times in a row (seen natively: up to 1 set creation
// in 150 on a one-line variable, 16 to 338 of 50,000).
inline constexpr std::uint64_t kPatientReadNs = 20'000'000;

struct TableHeader {
    std::uint32_t magic;        // kTableMagic
    std::uint32_t version;      // kTableVersion
    std::uint32_t capacity;     // entries
    std::uint32_t data_offset;  // value buffers, from the table's start (16-aligned)
    std::uint32_t data_size;    // their bytes
    A32 count;                  // published entries: [0, count)
    A32 data_used;              // bytes of the data area handed out
    std::uint32_t reserved0;
    bp::Lock lock;              // declarations and writer claims
    std::uint32_t reserved[4];
};

enum : std::uint32_t { kEntryFree = 0, kEntryLive = 1 };

struct Entry {
    A32 state;               // kEntryFree / kEntryLive
    std::uint32_t type;      // chm_svar_type_t
    std::uint32_t rows, cols;
    std::uint32_t bytes;     // one value
    std::uint32_t stride;    // bytes per buffer: `bytes` rounded up to 16
    std::uint32_t buf;       // buffer 0, from the table's start; buffer 1 follows
    A32 latest;              // number of the last complete write
    A32 bseq[2];             // per buffer: 2n+1 while write n goes in, 2n+2 after
    A32 writer_token;        // backplane token of the writer's process, 0: none
    A32 writer_id;           // the writing set's id in that process
    char name[kNameLen];
    char unit[kUnitLen];
    char writer_name[kNameLen];  // the writing set's owner (written before the token)
    // The instant from which the claim holds (a switch's T; 0: at once),
    // in two words written before the token: the writer it displaced
    // writes the cycles released before it and stops at the first after.
    A32 since_lo, since_hi;
    // The switch whose decision the claim waits on (written before the
    // token, with since): cell index + 1 (0: none) and its sequence. The
    // writer it displaces stops at T only if that switch was committed.
    A32 switch_cell, switch_seq;
    std::uint32_t reserved[4];
};

// Decision cells. A switch of modules across RTPUs takes one cell (OPEN)
// before its commits; every party reads it at T, the first instant the
// switch acts, and none acts unless the controller made it COMMITTED first:
// a party that finds it OPEN at T makes it ABORTED (one CAS decides who
// wins), so either every part switches or none. word = seq << 2 | state;
// the sequence grows with each use, so a stale reference never reads a
// later switch's outcome.
inline constexpr std::uint32_t kDecisionCells = 64;
enum : std::uint32_t { kCellFree = 0, kCellOpen = 1, kCellCommitted = 2, kCellAborted = 3 };
struct Cell {
    A32 word;
    A32 owner;  // the backplane token of the controller that opened it
};

static_assert(bp::kShared<TableHeader> && sizeof(TableHeader) == 64);
static_assert(bp::kShared<Entry> && sizeof(Entry) == 160);
static_assert(offsetof(Entry, name) == 48);
static_assert(bp::kShared<Cell> && sizeof(Cell) == 8);

inline constexpr std::uint32_t kTableBytesMin = sizeof(TableHeader) + sizeof(Entry) + kDecisionCells * sizeof(Cell);
inline std::uint64_t cells_offset(std::uint32_t capacity) {
    return sizeof(TableHeader) + std::uint64_t(capacity) * sizeof(Entry);
}

std::uint32_t elem_size(std::uint32_t type);  // 0 for an unknown type
inline std::uint32_t round16(std::uint32_t n) { return (n + 15u) & ~15u; }

// A process's checked view of the table: where it is, validated at open
// and kept in process memory, so an entry index or buffer offset changed
// in the file later cannot move an access outside the table.
struct Table {
    bp::Attachment* a = nullptr;
    std::uint32_t gen = 0;  // the attachment's generation when opened
    char* base = nullptr;   // table start
    std::uint32_t size = 0, capacity = 0, data_offset = 0, data_size = 0;
    TableHeader* hdr() const { return reinterpret_cast<TableHeader*>(base); }
    Entry* entry(std::uint32_t i) const {
        return reinterpret_cast<Entry*>(base + sizeof(TableHeader)) + i;
    }
    Cell* cell(std::uint32_t i) const { return reinterpret_cast<Cell*>(base + cells_offset(capacity)) + i; }
};

// A switch's decision cell as its parties name it; cell kNoCell: none.
inline constexpr std::uint32_t kNoCell = ~0u;
struct DecisionRef {
    std::uint32_t cell = kNoCell, seq = 0;
    bool none() const { return cell == kNoCell; }
    bool operator==(const DecisionRef&) const = default;
};

// An entry's immutable fields as validated (what a set keeps).
struct EntryView {
    std::uint32_t index, type, rows, cols, bytes, stride, buf;
    char name[kNameLen];
    char unit[kUnitLen];
};

// The table of the current attachment (opening, and with `create` making
// it). 0; -ENOENT no table and !create; -ENOTCONN; -EBADMSG (set_error
// names the field); -ENOMEM/-ENOSPC/-ETIMEDOUT creating it.
int open_table(bool create, Table* out);
// Check the table header at `base` (`size` bytes). 0 or bp::kCorrupt + why.
int validate_header(const char* base, std::uint32_t size, char* why, std::size_t n);
// Entry `i` of `t` as published: checked against the table's geometry.
// 0 or bp::kCorrupt with `why` naming the entry and field.
int read_entry(const Table& t, std::uint32_t i, EntryView* out, char* why, std::size_t n);
// The published count, checked against capacity (kCorrupt otherwise).
int published(const Table& t, std::uint32_t* count, char* why, std::size_t n);
// Index of the published entry called `name`, -ENOENT, or kCorrupt.
int find(const Table& t, const char* name, EntryView* out, char* why, std::size_t n);

// Lock the table for this process (repairing after a dead holder). 0,
// -ETIMEDOUT or kCorrupt.
int lock(const Table& t);
void unlock(const Table& t);
// After a holder died mid-declaration (lock held, dirty): an entry filled
// but not published is dropped, the data area's use recomputed.
void repair_locked(const Table& t);

// The data path. `e` is the shared entry, `buf0` its buffer 0 (checked).
// Copy the current value into `dst`: 0 or -EAGAIN after kReadAttempts.
int read_value(const Entry* e, const char* buf0, std::uint32_t stride, std::uint32_t bytes, void* dst);
void write_value(Entry* e, char* buf0, std::uint32_t stride, std::uint32_t bytes, const void* src);
// read_value again and again until a copy is consistent, for at most
// kPatientReadNs of real time: 0, or -EAGAIN (a sequence word that never
// settles is corrupt or belongs to a writer that laps every copy).
int read_value_patient(const Entry* e, const char* buf0, std::uint32_t stride, std::uint32_t bytes, void* dst);
// The error of a read_value_patient that gave up: "<fn> <owner>: <what>
// changed under every read for 20 ms (...)".
void set_unsettled_error(const char* fn, const char* owner, const char* what);

// Decision cells (decision.cpp). Open a FREE cell for a switch by the
// process of token `owner`: 0, or -EBUSY when every cell is taken.
int decision_open(const Table& t, std::uint32_t owner, DecisionRef* out);
// The state of `r`'s switch: kCellOpen, kCellCommitted, kCellAborted, or
// kCellFree when the cell no longer holds it (freed, reused, or `r` names
// no cell of the table).
std::uint32_t decision_peek(const Table& t, DecisionRef r);
// The controller, once every commit was acknowledged: OPEN -> COMMITTED.
// True if it did; false when a party reached T first and aborted.
bool decision_commit(const Table& t, DecisionRef r);
// Any party: settle the outcome now, OPEN -> ABORTED. The state after
// (kCellCommitted, kCellAborted), or kCellFree as for decision_peek.
std::uint32_t decision_settle(const Table& t, DecisionRef r);
// Give the cell back (every party knows the outcome); a no-op when it no
// longer holds `r`'s switch.
void decision_free(const Table& t, DecisionRef r);

// Is entry `e`'s writer claim held by a live writer? A claim of this
// process is live while the set it names exists (set.cpp); another
// process's while that process is.
bool claim_live(const Table& t, const Entry* e);
// set.cpp: is `id` one of this process's live sets?
bool set_alive(std::uint32_t id);

// set.cpp, for servo switches. The table a set reads.
const Table& set_table(const chm_svar_set* s);
// Claim every output from instant `since`, waiting on switch `r`'s
// decision (chm_svar_set_claim_at otherwise). 0 or as chm_svar_set_claim.
int set_claim_for_switch(chm_svar_set* s, const char* const* displace, std::size_t n_displace, std::uint64_t since,
                         DecisionRef r);
// Has an output of `s` been taken with an instant at or before `release`
// (chm_svar_set_displaced)? Then 1, and `*by` names the switch the claim
// waits on (none for a plain claim).
int set_displaced_by(const chm_svar_set* s, std::uint64_t release, DecisionRef* by);
// Switch `r` was aborted: take back every output of `s` that its claim
// took (or that is free), under the table lock. 0, or as chm_svar_set_claim.
int set_reclaim_after_abort(chm_svar_set* s, DecisionRef r);
// A module's copy-in and copy-out at each cycle (servo/cycle.cpp): what
// chm_svar_set_read and chm_svar_set_write do, without their per-call
// argument and attachment checks (the framework made the set, and the
// RTPU's attachment outlives the module), so a cycle touches no more
// code and data than the copies need. Same results (-EAGAIN, -EPERM).
int set_copy_in(chm_svar_set* s);
int set_copy_out(chm_svar_set* s);

}  // namespace chm::ipc::svar
// Its backplane hooks (svar_check, svar_validate, svar_recover) are
// declared with the other kinds' in backplane.hpp.
