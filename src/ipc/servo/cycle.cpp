// A module's cycles on its RTPU: the periodic task that exists while the
// module is ON (copy-in, cycle, copy-out at every release on the shared
// grid), and where a switch meets it: the first release at or after the
// switch's instant T reads the switch's outcome and acts only on a
// committed one (switch.cpp has the rest of the switch).
#include <cerrno>
#include <cstdio>
#include <cstring>

#include "chimera/bp.h"
#include "chimera/err.h"
#include "chimera/kernel.h"
#include "ipc/servo/host.hpp"
#include "lib/hot.hpp"

namespace chm::servo {

namespace {

constexpr std::uint64_t kStopWaitNs = 2'000'000'000ull;

chm_err_action_t record_cycle_error(const chm_err_info_t* i, void* arg) {
    return record_error_as(static_cast<chm_module*>(arg), "cycle: ", i);
}

chm_deadline_action on_miss(const chm_deadline_info_t* info, void* arg) {
    auto* m = static_cast<chm_module*>(arg);
    m->misses += info->unhandled;
    if (m->miss_policy == CHM_SERVO_MISS_ERROR) m->missed_error.store(true);
    return CHM_DL_CONTINUE;
}

// However the cycle task ends: a task that did not leave its loop itself
// was aborted (an error signal or a fault in cycle): the module is in
// ERROR from then on, its safe values out.
void on_cycle_end(void* arg) {
    auto* m = static_cast<chm_module*>(arg);
    chm_task_status_t st;
    if (chm_task_status(chm_task_self(), &st) == 0 && st.worst_cycle_cpu_ns > m->worst_ns)
        m->worst_ns = st.worst_cycle_cpu_ns;
    if (!m->cycle_done && m->state.load() == CHM_SERVO_ON) {
        if (!m->last_error[0]) set_last_error(m, "cycle: its task was ended");
        enter_error(m);
    }
}

void apply_pending(chm_module* m) {
    std::uint32_t mask = m->pending_mask.exchange(0, std::memory_order_acquire);
    while (mask) {
        const int k = __builtin_ctz(mask);
        m->params[k] = m->pending[k];
        mask &= mask - 1;
    }
}

// Switched on by a switch whose outcome is not "committed": undo `on` and
// give the outputs back, in this task, which has run no cycle.
void withdraw_switched_on(chm_module* m) {
    m->cycle_done = true;
    (void)m->desc->off(m);
    (void)chm_svar_set_release(m->set);
    m->on_at = 0;
    m->sw_arm.store(chm_module::kNotArmed);
    m->state.store(CHM_SERVO_OFF);
}

CHM_HOT void cycle_task(void* arg) {
    auto* m = static_cast<chm_module*>(arg);
    (void)chm_err_on_task(record_cycle_error, m);
    (void)chm_task_on_end(on_cycle_end, m);
    bool first = true;
    for (;;) {
        const std::uint64_t r = chm_task_cycle_release();
        // Switched on by a switch: its first release (at or after T) runs
        // only if the switch was committed; a resolve that cancelled it
        // first does the undoing.
        if (first && m->sw_arm.load() != chm_module::kNotArmed) {
            int armed = chm_module::kArmed;
            if (!m->sw_arm.compare_exchange_strong(armed, chm_module::kActing)) {
                m->cycle_done = true;
                return;
            }
            if (outcome_at_t(m, m->on_sw, switch_slot_ref(m->on_sw)) != svar::kCellCommitted) {
                withdraw_switched_on(m);
                return;
            }
            m->sw_arm.store(chm_module::kNotArmed);
        }
        // Read before off_by_switch: a stop armed by kill or teardown
        // clears the flag before it arms the instant.
        const std::uint64_t off = m->off_at();
        if (off && r >= off) {
            if (!m->off_by_switch.load() || outcome_at_t(m, m->off_sw, switch_slot_ref(m->off_sw)) == svar::kCellCommitted)
                break;
            m->arm_off(0);  // that switch was aborted: this module goes on
        }
        // Handed over: a module switched on at T took an output, so this
        // cycle (released at or after T) is the new writer's, if the
        // switch that took it was committed; if it was aborted, the
        // outputs are this module's again.
        svar::DecisionRef by;
        if (svar::set_displaced_by(m->set, r, &by)) {
            if (by.none() || outcome_at_t(m, m->off_sw, by) == svar::kCellCommitted) {
                m->arm_off(r);
                break;
            }
            (void)svar::set_reclaim_after_abort(m->set, by);
        }
        if (first) m->switched_at = r, first = false;
        if (m->pending_mask.load(std::memory_order_relaxed)) apply_pending(m);
        m->release_now = r;
        (void)svar::set_copy_in(m->set);  // -EAGAIN: an input keeps its last value
        const int rc = m->cycle_fn(m);
        m->release_now = 0;
        if (rc != 0 || m->missed_error.load()) {
            if (rc) set_last_error(m, "cycle returned %d", rc);
            else set_last_error(m, "deadline missed (miss policy: error)");
            m->cycle_done = true;
            enter_error(m);
            run_entry(m, kEntryError, rc ? rc : ETIME);
            return;
        }
        // The public call on failure only: it reports the error as before
        // (a set without its claim raises, which sends the module to ERROR).
        if (svar::set_copy_out(m->set) != 0) (void)chm_svar_set_write(m->set);
        ++m->cycles;
        chm_task_wait_period();
    }
    // Switched off at the first release at or after off_at: this cycle and
    // every later one belong to the module that took over.
    m->switched_at = m->off_at();
    m->cycle_done = true;
    switch_slot_clear(m->off_sw);  // acted on: nothing of that switch is pending here
    m->off_by_switch.store(false);
    if (m->desc->off(m) != 0) {
        set_last_error(m, "off failed");
        enter_error(m);
        return;
    }
    (void)chm_svar_set_release(m->set);
    m->arm_off(0);
    m->state.store(CHM_SERVO_OFF);
}

}  // namespace

std::uint64_t grid_at_or_after(std::uint64_t t, std::uint64_t period) {
    return (t + period - 1) / period * period;
}

int spawn_cycle_task(chm_module* m, std::uint64_t start) {
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    char name[CHM_TASK_NAME_MAX + 1];
    std::snprintf(name, sizeof name, "%s", m->name);
    a.name = name;
    a.priority = m->priority;
    a.critical = m->critical;
    a.period_ns = m->period_ns;
    a.deadline_ns = m->deadline_ns;
    a.wcet_ns = m->wcet_ns;
    a.start_ns = start;
    a.on_deadline = on_miss;
    a.on_deadline_arg = m;
    a.joinable = 1;
    m->cycle_done = false;
    m->missed_error.store(false);
    return chm_task_spawn(&m->cycle_task, cycle_task, m, &a);
}

void reap_cycle_task(chm_module* m) {
    if (m->cycle_task == CHM_TID_NONE) return;
    chm_task_status_t st;
    if (chm_task_status(m->cycle_task, &st) == 0 && st.state == CHM_TASK_ENDED) {
        (void)chm_task_join(m->cycle_task, CHM_NO_WAIT, nullptr);
        m->cycle_task = CHM_TID_NONE;
    }
}

void stop_cycle_task(chm_module* m) {
    if (m->cycle_task == CHM_TID_NONE) return;
    m->off_by_switch.store(false);  // before the instant: the cycle task reads them in the other order
    m->arm_off(1);  // every release is at or after 1
    if (chm_task_join(m->cycle_task, kStopWaitNs, nullptr) == -ETIMEDOUT) {
        (void)chm_task_destroy(m->cycle_task);
        (void)chm_task_join(m->cycle_task, CHM_NO_WAIT, nullptr);
        if (m->state.load() == CHM_SERVO_ON) run_entry(m, kEntryOff);
    }
    m->cycle_task = CHM_TID_NONE;
    (void)chm_svar_set_release(m->set);
    m->arm_off(0);
    if (m->state.load() == CHM_SERVO_ON) m->state.store(CHM_SERVO_OFF);
}

}  // namespace chm::servo
