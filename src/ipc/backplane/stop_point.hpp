// Named stop points: CHM_STOP_POINT("bp.take_slot.before_cas") marks an
// instant of a backplane protocol where a process may stall (preempted,
// stopped, traced). A process started with CHIMERA_STOP_AT=<name> stops
// itself there (SIGSTOP, the whole process) the first time it passes that
// point, so a test can hold it at exactly that instant, act on the
// backplane from other processes, then SIGCONT it (tests/ipc/test_ipc_races.cpp).
// A list, CHIMERA_STOP_AT=<a>,<b>, stops at each of them once: a test that
// holds a process at two instants of one call.
//
// The same points inject faults: CHIMERA_FAULT_AT=<name>:<action> does,
// the first time a task (or for kill, any thread) passes <name>: `abort`
// (an error signal, which the default handler answers by aborting the
// task), `fault` (a processor exception: a store to address 0), `destroy`
// (chm_task_destroy of the task itself), `abort_cycle` (as a deadline
// handler's CHM_DL_ABORT_CYCLE), `kill` (SIGKILL, the process) or `stop`
// (as CHIMERA_STOP_AT). An unknown action is reported on stderr and
// nothing is injected. tests/ipc/test_ipc_fault.cpp runs every point with
// every action.
//
// Off (the variables unset, the normal case) a point costs one load of a
// cached flag and one branch predicted not taken. The variables are read
// once, at the first point a process passes. Names are "<area>.<function>.
// <instant>".
#pragma once

#include <atomic>

namespace chm::stop {

// 0: not read yet, 1: off, 2: armed (a name is set), 3: being read.
extern std::atomic<int> g_state;

// The slow path: reads the environment on first use; stops the process
// when `name` is the armed point (once per process).
void hit(const char* name);

// Forget what was read and re-arm, so the next point reads the
// environment again: for a forked child that set CHIMERA_STOP_AT after
// its parent had already passed a point, or a test that injects the same
// fault again.
void reload();

}  // namespace chm::stop

#define CHM_STOP_POINT(name)                                                            \
    do {                                                                               \
        if (__builtin_expect(::chm::stop::g_state.load(std::memory_order_relaxed) != 1, 0)) \
            ::chm::stop::hit(name);                                                    \
    } while (0)
