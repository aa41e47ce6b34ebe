// Decision cells of servo switches (svar.hpp, "Decision cells"): taken by
// a controller, settled by one CAS by whoever comes first — the controller
// committing once every RTPU acknowledged, or any party aborting when T
// arrives and the cell is still open — and given back by the controller.
#include <cerrno>

#include "ipc/svar/svar.hpp"
#include "ipc/backplane/backplane.hpp"  // token_alive

namespace chm::ipc::svar {

namespace {
constexpr auto Acq = std::memory_order_acquire;
constexpr auto AcqRel = std::memory_order_acq_rel;
constexpr std::uint32_t kSeqMask = 0x3fffffffu;

std::uint32_t state_of(std::uint32_t w) { return w & 3u; }
std::uint32_t seq_of(std::uint32_t w) { return w >> 2; }
std::uint32_t word(std::uint32_t seq, std::uint32_t state) { return (seq & kSeqMask) << 2 | state; }

// The cell `r` names, if it is one of the table's (the reference may come
// from a request or a table entry: neither is believed unchecked).
Cell* cell_of(const Table& t, DecisionRef r) { return r.cell < kDecisionCells ? t.cell(r.cell) : nullptr; }

// Open cell `c` (number `i`) for `owner` if it is FREE.
bool open_free(Cell* c, std::uint32_t i, std::uint32_t owner, DecisionRef* out) {
    std::uint32_t w = c->word.load(Acq);
    if (state_of(w) != kCellFree) return false;
    const std::uint32_t seq = (seq_of(w) + 1) & kSeqMask ? (seq_of(w) + 1) & kSeqMask : 1;
    if (!c->word.compare_exchange_strong(w, word(seq, kCellOpen), AcqRel)) return false;
    c->owner.store(owner, std::memory_order_release);
    *out = DecisionRef{i, seq};
    return true;
}

// A cell whose controller died before it gave the cell back. Still OPEN or
// ABORTED, it is settled ABORTED and freed: its parties would abort it at
// T themselves (nobody can commit it now), and a party that reads it
// freed takes it for aborted too. One the controller had COMMITTED stays
// taken: a party that has not reached T yet may not know the outcome, and
// would read the freed cell as aborted while the others switched.
bool reclaim_dead(const Table& t, Cell* c, std::uint32_t i) {
    const std::uint32_t w = c->word.load(Acq);
    const std::uint32_t st = state_of(w);
    if (st != kCellOpen && st != kCellAborted) return false;
    // Owner 0: opened an instant ago, its token not stored yet (or never
    // recorded): not a dead controller's (token_alive(0) is true).
    const std::uint32_t owner = c->owner.load(Acq);
    if (owner == t.a->token || bp::token_alive(*t.a, owner, true)) return false;
    const DecisionRef r{i, seq_of(w)};
    if (decision_settle(t, r) != kCellAborted) return false;  // committed meanwhile, or reused
    decision_free(t, r);
    return true;
}

}  // namespace

int decision_open(const Table& t, std::uint32_t owner, DecisionRef* out) {
    for (std::uint32_t i = 0; i < kDecisionCells; ++i)
        if (open_free(t.cell(i), i, owner, out)) return 0;
    // Every cell taken: give back a dead controller's and take it.
    for (std::uint32_t i = 0; i < kDecisionCells; ++i)
        if (reclaim_dead(t, t.cell(i), i) && open_free(t.cell(i), i, owner, out)) return 0;
    return -EBUSY;
}

std::uint32_t decision_peek(const Table& t, DecisionRef r) {
    const Cell* c = cell_of(t, r);
    if (!c) return kCellFree;
    const std::uint32_t w = c->word.load(Acq);
    return seq_of(w) == r.seq ? state_of(w) : kCellFree;
}

bool decision_commit(const Table& t, DecisionRef r) {
    Cell* c = cell_of(t, r);
    std::uint32_t w = word(r.seq, kCellOpen);
    return c && c->word.compare_exchange_strong(w, word(r.seq, kCellCommitted), AcqRel);
}

std::uint32_t decision_settle(const Table& t, DecisionRef r) {
    Cell* c = cell_of(t, r);
    if (!c) return kCellFree;
    std::uint32_t w = word(r.seq, kCellOpen);
    if (c->word.compare_exchange_strong(w, word(r.seq, kCellAborted), AcqRel)) return kCellAborted;
    // Not open: w holds what the cell says now.
    return seq_of(w) == r.seq && state_of(w) != kCellFree ? state_of(w) : kCellFree;
}

void decision_free(const Table& t, DecisionRef r) {
    Cell* c = cell_of(t, r);
    if (!c) return;
    std::uint32_t w = c->word.load(Acq);
    // Still this switch's and decided: nobody else can open or free it
    // now, so its owner can be cleared first. A cell is then ownerless
    // (token 0, never dead) from its freeing until its next opener stores
    // its token just after the CAS that opened it: a reclaim in between
    // (reclaim_dead) must not take that cell for a dead controller's.
    if (seq_of(w) == r.seq && state_of(w) >= kCellCommitted) c->owner.store(0, std::memory_order_release);
    while (seq_of(w) == r.seq && state_of(w) >= kCellCommitted)  // an open switch is never freed
        if (c->word.compare_exchange_weak(w, word(r.seq, kCellFree), AcqRel)) return;
}

}  // namespace chm::ipc::svar
