// A switch on the RTPU side: prepare (nothing changes), commit (armed for
// instant T, conditionally on the switch's decision cell), resolve (the
// controller's outcome), and how a module learns the outcome at T. The
// protocol is in docs/architecture.md, "A switch".
#include <cerrno>
#include <cstdio>
#include <cstring>

#include "chimera/bp.h"
#include "chimera/kernel.h"
#include "ipc/backplane/stop_point.hpp"
#include "ipc/servo/host.hpp"

namespace chm::servo {

namespace {

using Slot = chm_module::SwitchSlot;

bool names(const Slot& s, svar::DecisionRef r) { return s.cell.load() == r.cell && s.seq.load() == r.seq; }

void assign(Slot& s, svar::DecisionRef r) {
    s.outcome.store(0);
    s.seq.store(r.seq);
    s.cell.store(r.cell);
}

// A slot of `m` whose outcome never reached it (its controller died, or
// this RTPU missed the resolve): learn it from the cell. True while that
// switch is still open.
bool still_open(chm_module* m, Slot& s) {
    const svar::DecisionRef r = switch_slot_ref(s);
    if (r.none() || s.outcome.load()) return false;
    const std::uint32_t o = svar::decision_peek(svar::set_table(m->set), r);
    if (o == svar::kCellOpen) return true;
    if (o != svar::kCellFree) s.outcome.store(o);
    return false;
}

// Switched on by an aborted switch, before its first release: the task
// goes before it runs anything, `on` is undone, the outputs given back.
void cancel_switched_on(chm_module* m) {
    int armed = chm_module::kArmed;
    if (!m->sw_arm.compare_exchange_strong(armed, chm_module::kCancelled)) return;  // its task decided
    // Done before the destroy: its end hook must not take this for a
    // fault (ERROR would write safe values into variables another module
    // still writes).
    m->cycle_done = true;
    (void)chm_task_destroy(m->cycle_task);
    (void)chm_task_join(m->cycle_task, CHM_NO_WAIT, nullptr);
    m->cycle_task = CHM_TID_NONE;
    run_entry(m, kEntryOff);
    (void)chm_svar_set_release(m->set);
    m->on_at = 0;
    m->sw_arm.store(chm_module::kNotArmed);
    m->state.store(CHM_SERVO_OFF);
}

}  // namespace

svar::DecisionRef switch_slot_ref(const chm_module::SwitchSlot& s) {
    const std::uint32_t cell = s.cell.load();
    return cell == svar::kNoCell ? svar::DecisionRef{} : svar::DecisionRef{cell, s.seq.load()};
}

void switch_slot_clear(chm_module::SwitchSlot& s) {
    s.cell.store(svar::kNoCell);
    s.outcome.store(0);
}

std::uint32_t outcome_at_t(chm_module* m, chm_module::SwitchSlot& slot, svar::DecisionRef sw) {
    const bool mine = names(slot, sw);
    if (mine)
        if (const std::uint32_t o = slot.outcome.load()) return o;
    std::uint32_t o = svar::decision_settle(svar::set_table(m->set), sw);
    // Freed: the controller had told every part first (this one too).
    if (o == svar::kCellFree && mine) o = slot.outcome.load();
    if (o != svar::kCellCommitted && o != svar::kCellAborted) {
        // Only a table changed under us gets here: do not act.
        set_last_error(m, "switch at T: its decision cell %u no longer holds it; not switched", sw.cell);
        o = svar::kCellAborted;
    }
    if (mine) slot.outcome.store(o);
    return o;
}

int prepare(const Item* items, std::uint32_t count, const char* const* displace, std::uint32_t n_displace, char* why,
            std::size_t n) {
    for (std::uint32_t i = 0; i < count; ++i) {
        chm_module* m = items[i].m;
        reap_cycle_task(m);
        const int st = m->state.load();
        if (still_open(m, m->on_sw) || still_open(m, m->off_sw))
            return std::snprintf(why, n, "%s is in a switch still under way", m->name), -EALREADY;
        if (!items[i].on && st == CHM_SERVO_ON && m->off_sw.outcome.load() == svar::kCellCommitted)
            return std::snprintf(why, n, "%s goes off at an earlier switch already", m->name), -EALREADY;
        if (items[i].on && st != CHM_SERVO_OFF)
            return std::snprintf(why, n, "%s is not OFF (state %d): cannot go on", m->name, st), -EALREADY;
        if (!items[i].on && (st != CHM_SERVO_ON || m->off_at()))
            return std::snprintf(why, n, "%s is not ON: cannot go off", m->name), -EALREADY;
        if (items[i].on && m->cycle_task != CHM_TID_NONE)
            return std::snprintf(why, n, "%s is still finishing its last cycle", m->name), -EALREADY;
    }
    // Could each module going on claim its outputs? Asked without taking
    // anything: a claim, even one given back at once, would tell the
    // writer it displaces to stop.
    for (std::uint32_t i = 0; i < count; ++i) {
        if (!items[i].on) continue;
        if (int r = chm_svar_set_check_claim(items[i].m->set, displace, n_displace)) {
            std::snprintf(why, n, "%s", chm_bp_last_error());
            return r;
        }
    }
    return 0;
}

int commit(std::uint64_t at, svar::DecisionRef sw, const Item* items, std::uint32_t count, const char* const* displace,
           std::uint32_t n_displace, char* why, std::size_t n) {
    // Where a test holds this RTPU between its prepare and its commit.
    CHM_STOP_POINT("servo.commit.begin");
    if (count == 0) return 0;
    if (svar::decision_peek(svar::set_table(items[0].m->set), sw) != svar::kCellOpen)
        return std::snprintf(why, n, "the switch was already decided (aborted at its instant): nothing switched here"),
               -ETIME;
    // A module handed over needs nothing armed (it stops when its outputs
    // are taken, if the switch is committed); the others are checked again.
    // Every module learns the switch first: each reads its outcome at T.
    Item rest[kSwitchMax] = {};
    std::uint32_t n_rest = 0;
    for (std::uint32_t i = 0; i < count; ++i) {
        if (!items[i].handed) rest[n_rest++] = items[i];
    }
    if (int r = prepare(rest, n_rest, displace, n_displace, why, n)) return r;
    for (std::uint32_t i = 0; i < count; ++i) {
        chm_module* m = items[i].m;
        if (items[i].on) {
            assign(m->on_sw, sw);
            switch_slot_clear(m->off_sw);
        } else {
            assign(m->off_sw, sw);
        }
    }
    items = rest;
    count = n_rest;
    // `on` runs first for every module going on; a failure undoes the
    // others before anything is armed, and T must still be ahead after.
    std::uint32_t done = 0;
    int r = 0;
    for (; done < count && r == 0; ++done) {
        chm_module* m = items[done].m;
        if (!items[done].on) continue;
        if (run_entry(m, kEntryOn) != 0) {
            r = -ECANCELED;
            std::snprintf(why, n, "%s: %s", m->name, m->last_error);
            enter_error(m);
        }
    }
    if (r == 0 && chm_time_now() >= at) {
        r = -ETIME;
        std::snprintf(why, n, "the switch instant passed before this RTPU was ready (nothing switched here)");
    }
    if (r) {
        for (std::uint32_t i = 0; i + 1 < done; ++i)
            if (items[i].on) run_entry(items[i].m, kEntryOff);
        return r;
    }
    // Where a test holds this RTPU after that look at the clock, until T
    // has passed: the cycle tasks below are then spawned released.
    CHM_STOP_POINT("servo.commit.armed_late");
    std::uint32_t armed = 0;
    for (; armed < count && r == 0; ++armed) {
        chm_module* m = items[armed].m;
        if (!items[armed].on) continue;
        if ((r = svar::set_claim_for_switch(m->set, displace, n_displace, at, sw)) != 0) {
            std::snprintf(why, n, "%s", chm_bp_last_error());
            break;
        }
        // All of it before the spawn: once T has passed, the task runs at
        // once (more urgent than this server) and may withdraw the module
        // (switch undecided at T), which must be the last word.
        m->sw_arm.store(chm_module::kArmed);
        m->on_at = at;
        m->state.store(CHM_SERVO_ON);
        if ((r = spawn_cycle_task(m, grid_at_or_after(at, m->period_ns))) != 0) {
            m->sw_arm.store(chm_module::kNotArmed);
            m->on_at = 0;
            m->state.store(CHM_SERVO_OFF);
            (void)chm_svar_set_release(m->set);
            std::snprintf(why, n, "%s: cannot spawn its cycle task (%d)", m->name, r);
            break;
        }
    }
    if (r) {
        // Those armed lose their task; the failing one and those after it
        // ran `on` only.
        for (std::uint32_t i = 0; i < count; ++i) {
            if (!items[i].on) continue;
            if (i < armed) cancel_switched_on(items[i].m);
            else run_entry(items[i].m, kEntryOff);
        }
        return r;
    }
    // Modules going off alone stop at their first release at or after T,
    // if the switch is committed by then.
    for (std::uint32_t i = 0; i < count; ++i) {
        if (items[i].on) continue;
        items[i].m->off_by_switch.store(true);  // before the instant: the cycle task reads them in the other order
        items[i].m->arm_off(at);
    }
    return 0;
}

int resolve(svar::DecisionRef sw, std::uint32_t outcome, const Item* items, std::uint32_t count, char* why,
            std::size_t n) {
    if (outcome != svar::kCellCommitted && outcome != svar::kCellAborted)
        return std::snprintf(why, n, "malformed resolve: outcome %u", outcome), -EINVAL;
    for (std::uint32_t i = 0; i < count; ++i) {
        chm_module* m = items[i].m;
        if (names(m->on_sw, sw)) m->on_sw.outcome.store(outcome);
        if (names(m->off_sw, sw)) m->off_sw.outcome.store(outcome);
    }
    if (outcome == svar::kCellCommitted) return 0;
    // Aborted. Where a module has not reached T itself, undo now what
    // commit armed; where it has, it already saw the same outcome.
    for (std::uint32_t i = 0; i < count; ++i) {
        chm_module* m = items[i].m;
        if (items[i].on) {
            if (names(m->on_sw, sw)) cancel_switched_on(m);
        } else if (items[i].handed) {
            (void)svar::set_reclaim_after_abort(m->set, sw);
        } else if (names(m->off_sw, sw) && m->off_by_switch.load()) {
            m->arm_off(0);
        }
    }
    return 0;
}

}  // namespace chm::servo
