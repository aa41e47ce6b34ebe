// What a task holds inside a backplane call, and the ends that wait for
// the call (issue 15, "a task that ends inside a backplane call leaves
// nothing behind"). Used by src/ipc/ (internal; no public API).
//
//  * Holds. A backplane lock or waiter record belongs to the process (its
//    token), not the task, so no one else can tell that the task which
//    took it has ended. The taker records it on its hold list (hold_add,
//    hold_drop when it gives it back); however the task ends (error-signal
//    abort, processor exception, exit from a handler, destroy, teardown)
//    the list is unwound, newest first, by each hold's release function,
//    in the ending task's context or its destroyer's, mask free.
//  * Calls. A public backplane call is a CallScope. Destroy (local or by
//    express mail) and abort-cycle of a task inside one are owed, not
//    done: the call's wait is a cancellation point (it returns -EINTR
//    and the call withdraws as for a user signal), and the owed end or
//    restart is carried out when the outermost call returns. User signal
//    and deadline handlers run inside a call only at its wait, never
//    while it holds an object's lock.
//
// Outside a task on the kernel thread (host threads, the monitor thread,
// an interrupt handler) all of this does nothing.
#pragma once

#include <atomic>
#include <cstdint>

namespace chm::kernel {

// Set once a kernel was initialised in this process: before that no
// thread is a task, and every call below is one load and a branch (a
// host program's backplane calls pay nothing more). Atomic, relaxed: the
// backplane monitor thread (started at the join, before the kernel's init)
// reads it in its recovery's lock calls while the main thread sets it; a
// relaxed load is the same plain load.
extern std::atomic<bool> g_tasks_exist;

inline bool tasks_exist() { return g_tasks_exist.load(std::memory_order_relaxed); }

bool hold_add_slow(void (*release)(void*, std::uint32_t), void* obj, std::uint32_t tag);
void hold_drop_slow(void* obj);
void call_enter_slow();
void call_leave_slow();

// Record that the calling task holds `obj` (with `tag`, e.g. the token
// it took a lock with); release(obj, tag) gives it back if the task ends
// before hold_drop(obj). False when not a task (nothing recorded) or the
// list is full (Tcb::kMaxHolds; not released then).
inline bool hold_add(void (*release)(void*, std::uint32_t), void* obj, std::uint32_t tag) {
    return __builtin_expect(tasks_exist(), 1) && hold_add_slow(release, obj, tag);
}
// The calling task gave `obj` back (newest matching entry); no-op when
// it is not on the list.
inline void hold_drop(void* obj) {
    if (__builtin_expect(tasks_exist(), 1)) hold_drop_slow(obj);
}

// A backplane call begins and ends (CallScope).
inline void call_enter() {
    if (__builtin_expect(tasks_exist(), 1)) call_enter_slow();
}
inline void call_leave() {
    if (__builtin_expect(tasks_exist(), 1)) call_leave_slow();
}

// True when the calling task's wait must end now: it was destroyed or its
// cycle aborted inside the call.
bool cancel_owed();

// Abort the calling task's cycle as a deadline handler's CHM_DL_ABORT_CYCLE
// does (owed until the call returns when inside one); the fault injection
// of stop_point.hpp. No-op for a task that is not periodic.
void abort_cycle_current();

// RAII form of call_enter / call_leave.
struct CallScope {
    CallScope() { call_enter(); }
    ~CallScope() { call_leave(); }
    CallScope(const CallScope&) = delete;
    CallScope& operator=(const CallScope&) = delete;
};

}  // namespace chm::kernel
