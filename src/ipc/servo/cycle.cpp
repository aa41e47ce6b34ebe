// A module's cycles and its part in a switch, on its RTPU: the periodic
// task that exists while the module is ON (copy-in, cycle, copy-out at
// every release on the shared grid), and prepare / commit / cancel.
#include <cerrno>
#include <cstdio>
#include <cstring>

#include "chimera/bp.h"
#include "chimera/err.h"
#include "chimera/kernel.h"
#include "ipc/servo/host.hpp"

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

void cycle_task(void* arg) {
    auto* m = static_cast<chm_module*>(arg);
    (void)chm_err_on_task(record_cycle_error, m);
    (void)chm_task_on_end(on_cycle_end, m);
    bool first = true;
    for (;;) {
        const std::uint64_t r = chm_task_cycle_release();
        const std::uint64_t off = m->off_at();
        if (off && r >= off) break;
        // Handed over: a module switched on at T took an output, so this
        // cycle (released at or after T) is the new writer's.
        if (chm_svar_set_displaced(m->set, r)) {
            m->arm_off(r);
            break;
        }
        if (first) m->switched_at = r, first = false;
        if (m->pending_mask.load(std::memory_order_relaxed)) apply_pending(m);
        m->release_now = r;
        (void)chm_svar_set_read(m->set);  // -EAGAIN: an input keeps its last value
        const int rc = m->desc->cycle(m);
        m->release_now = 0;
        if (rc != 0 || m->missed_error.load()) {
            if (rc) set_last_error(m, "cycle returned %d", rc);
            else set_last_error(m, "deadline missed (miss policy: error)");
            m->cycle_done = true;
            enter_error(m);
            run_entry(m, kEntryError, rc ? rc : ETIME);
            return;
        }
        (void)chm_svar_set_write(m->set);
        ++m->cycles;
        chm_task_wait_period();
    }
    // Switched off at the first release at or after off_at: this cycle and
    // every later one belong to the module that took over.
    m->switched_at = m->off_at();
    m->cycle_done = true;
    if (m->desc->off(m) != 0) {
        set_last_error(m, "off failed");
        enter_error(m);
        return;
    }
    (void)chm_svar_set_release(m->set);
    m->arm_off(0);
    m->state.store(CHM_SERVO_OFF);
}

// The first multiple of `period` at or after `t`.
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

// Forget a cycle task that has ended (its slot is freed).
void reap_cycle_task(chm_module* m) {
    if (m->cycle_task == CHM_TID_NONE) return;
    chm_task_status_t st;
    if (chm_task_status(m->cycle_task, &st) == 0 && st.state == CHM_TASK_ENDED) {
        (void)chm_task_join(m->cycle_task, CHM_NO_WAIT, nullptr);
        m->cycle_task = CHM_TID_NONE;
    }
}

}  // namespace

void stop_cycle_task(chm_module* m) {
    if (m->cycle_task == CHM_TID_NONE) return;
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

int prepare(const Item* items, std::uint32_t count, const char* const* displace, std::uint32_t n_displace, char* why,
            std::size_t n) {
    for (std::uint32_t i = 0; i < count; ++i) {
        chm_module* m = items[i].m;
        reap_cycle_task(m);
        const int st = m->state.load();
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

int commit(std::uint64_t at, const Item* items, std::uint32_t count, const char* const* displace,
           std::uint32_t n_displace, char* why, std::size_t n) {
    // A module handed over needs nothing here (it stops when its outputs
    // are taken, and may have done so already if this commit is late);
    // the others are checked again.
    Item rest[kSwitchMax] = {};
    std::uint32_t n_rest = 0;
    for (std::uint32_t i = 0; i < count; ++i)
        if (!items[i].handed) rest[n_rest++] = items[i];
    if (int r = prepare(rest, n_rest, displace, n_displace, why, n)) return r;
    items = rest;
    count = n_rest;
    bool any_on = false;
    for (std::uint32_t i = 0; i < count; ++i) any_on |= items[i].on;
    if (!any_on) {
        // Only modules going off alone: each stops at its first release at
        // or after T (at once when this commit comes later than T).
        for (std::uint32_t i = 0; i < count; ++i) items[i].m->arm_off(at);
        return 0;
    }
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
    for (std::uint32_t i = 0; i < count && r == 0; ++i) {
        chm_module* m = items[i].m;
        if (!items[i].on) continue;
        if ((r = chm_svar_set_claim_at(m->set, displace, n_displace, at)) != 0) {
            std::snprintf(why, n, "%s", chm_bp_last_error());
        } else if ((r = spawn_cycle_task(m, grid_at_or_after(at, m->period_ns))) != 0) {
            std::snprintf(why, n, "%s: cannot spawn its cycle task (%d)", m->name, r);
        } else {
            m->on_at = at;
            m->state.store(CHM_SERVO_ON);
        }
    }
    if (r) {
        cancel(at, items, count, displace, n_displace, why, 0);
        return r;
    }
    // A module handed over stops when it finds its outputs taken (at T,
    // if the module taking them was committed in time, else never): the
    // variable is never without a writer. The others stop at T.
    for (std::uint32_t i = 0; i < count; ++i)
        if (!items[i].on && !items[i].handed) items[i].m->arm_off(at);
    return 0;
}

int cancel(std::uint64_t at, const Item* items, std::uint32_t count, const char* const* displace,
           std::uint32_t n_displace, char* why, std::size_t n) {
    if (chm_time_now() >= at) {
        if (n) std::snprintf(why, n, "the switch instant has passed: too late to cancel");
        return -ETIME;
    }
    // Must beat T: nothing here may block long (off runs in a bounded task).
    // Modules going on that were armed lose their task before its first
    // release and run off; modules going off keep running and take back
    // their outputs from the modules that displaced them (`displace` here
    // names every module going on, on any RTPU).
    for (std::uint32_t i = 0; i < count; ++i) {
        chm_module* m = items[i].m;
        if (!items[i].on || m->on_at != at || m->state.load() != CHM_SERVO_ON) continue;
        // Done before the destroy: its end hook must not take this for a
        // fault (ERROR would write safe values into variables another
        // module still writes).
        m->cycle_done = true;
        (void)chm_task_destroy(m->cycle_task);
        (void)chm_task_join(m->cycle_task, CHM_NO_WAIT, nullptr);
        m->cycle_task = CHM_TID_NONE;
        run_entry(m, kEntryOff);
        (void)chm_svar_set_release(m->set);
        m->on_at = 0;
        m->state.store(CHM_SERVO_OFF);
    }
    for (std::uint32_t i = 0; i < count; ++i) {
        chm_module* m = items[i].m;
        if (items[i].on) continue;
        if (m->off_at() == at) m->arm_off(0);
        (void)chm_svar_set_claim(m->set, displace, n_displace);
    }
    return 0;
}

}  // namespace chm::servo
