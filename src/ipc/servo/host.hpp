// The RTPU side of servo task control: the module table of this RTPU and
// the operations serve.cpp decodes requests into. All run on the RTPU's
// express-mail server task, except the cycle task's own work (cycle.cpp).
// `why` (n bytes) receives the reason of a refusal.
#pragma once

#include <cstddef>
#include <cstdint>

#include "chimera/err.h"
#include "ipc/servo/servo.hpp"
#include "ipc/svar/svar.hpp"

namespace chm::servo {

// The module at `ref`, if it exists with that generation.
chm_module* lookup(Ref ref);
chm_module* find_name(const char* name);

int take(std::uint32_t from, char* why, std::size_t n);
int release(std::uint32_t from);
// May `from` change modules here? (It holds control.)
bool controls(std::uint32_t from);

int spawn(const SpawnReq& q, const ParamOverride* params, const char* path, Ref* out, char* why, std::size_t n);
int control(chm_module* m, const char* param, double value, char* why, std::size_t n);
int clear(chm_module* m, char* why, std::size_t n);
int kill(chm_module* m, char* why, std::size_t n);
void status(const chm_module* m, StatusReply* out);

namespace svar = chm::ipc::svar;

// The switch (switch.cpp). `items` are this RTPU's part; `displace` the
// instance names of every module going off (any RTPU); `sw` the switch's
// decision cell, which its controller opened.
struct Item {
    chm_module* m;
    bool on;
    bool handed;  // going off because a module going on takes its outputs
};
int prepare(const Item* items, std::uint32_t count, const char* const* displace, std::uint32_t n_displace, char* why,
            std::size_t n);
// Arm this part for instant `at`, conditionally: nothing acts at T unless
// the controller commits the cell first. Refused when the cell is no longer
// open or T is too near.
int commit(std::uint64_t at, svar::DecisionRef sw, const Item* items, std::uint32_t count, const char* const* displace,
           std::uint32_t n_displace, char* why, std::size_t n);
// The controller tells this part the outcome (svar::kCellCommitted or
// kCellAborted). Aborted: what commit armed is undone now, where the
// module has not reached T itself.
int resolve(svar::DecisionRef sw, std::uint32_t outcome, const Item* items, std::uint32_t count, char* why,
            std::size_t n);
// A module at its first release at or after T: the outcome of switch `sw`
// as this module knows it (in `slot`, its on_sw or off_sw), else settled
// in the cell now (open -> aborted).
std::uint32_t outcome_at_t(chm_module* m, chm_module::SwitchSlot& slot, svar::DecisionRef sw);
svar::DecisionRef switch_slot_ref(const chm_module::SwitchSlot& s);
void switch_slot_clear(chm_module::SwitchSlot& s);

// The cycle task (cycle.cpp). The first multiple of `period` at or after
// `t`; spawn the module's cycle task with first release `start`; forget a
// cycle task that has ended (its slot freed).
std::uint64_t grid_at_or_after(std::uint64_t t, std::uint64_t period);
int spawn_cycle_task(chm_module* m, std::uint64_t start);
void reap_cycle_task(chm_module* m);

// Entry points in their own task (host.cpp): 0, or -ECANCELED with the
// module's last_error saying why (returned code, error signal, fault).
enum Entry { kEntryInit, kEntryOn, kEntryOff, kEntryKill, kEntryClear, kEntryError };
int run_entry(chm_module* m, Entry e, int code = 0);
// ERROR: the safe values written, last_error kept (any task).
void enter_error(chm_module* m);
// Stop a module's cycle task now (kill, teardown): ask it to stop at its
// next release and wait for it, bounded; destroy it after that.
void stop_cycle_task(chm_module* m);

void set_last_error(chm_module* m, const char* fmt, ...) __attribute__((format(printf, 2, 3)));
// The task-wide error handler of a module's tasks: an error signal or a
// processor exception becomes its last error (`prefix` first), and the
// task ends.
chm_err_action_t record_error_as(chm_module* m, const char* prefix, const chm_err_info_t* i);

}  // namespace chm::servo
