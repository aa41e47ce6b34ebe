// Waiting on a word in shared memory: the kernel side of every backplane
// wait (remote semaphores, message queues, express-mail replies). A task
// parks until another process sets the word non-zero and rings this
// RTPU's doorbell with the grant vector; only the task waits, never the
// RTPU. Used by src/ipc/ (internal; the public calls are chm_rsem_*,
// chm_msgq_*).
#pragma once

#include <cstdint>

#include "port.hpp"

namespace chm::kernel {

// The mailbox vector the kernel reserves for grants (chimera/irq.h 0..31).
inline constexpr int kGrantVector = 31;

// True when the caller is a task that can park (kernel thread, in a task,
// not locked into the CPU, not in an interrupt handler).
bool remote_wait_possible();

// The calling task's static priority (0 outside a task): what a waiter
// record on the backplane ranks by. O(1), unlike chm_task_status (which
// measures the stack's high-water mark).
int remote_waiter_priority();

// What a granter needs to decide whether waking the caller must interrupt
// its RTPU (port::RingFor), recorded beside the word it waits on:
//  * its id as this RTPU publishes it while it runs (never 0; 0 when the
//    caller is not a task that can park);
//  * its urgency on the scale this RTPU publishes for the running task:
//    the static part of the policy's order (MUF's critical set, a deadline
//    or RM period before none, then the priority or RM's period), so a
//    grant to a waiter that does not outrank the running task waits for
//    the next switch or scheduler run. Where the order moves while a task
//    runs (two tasks with deadlines under EDF, MLF or MUF) the waiter's
//    urgency is the highest of its class and the running task's the
//    lowest, so the grant interrupts and the RTPU's scheduler decides.
std::uint32_t remote_waiter_id();
std::uint32_t remote_waiter_urgency();

// Publish the running task (g_k.current) on the RTPU's doorbell: called at
// every switch, and when the doorbell is bound. Mask held.
void publish_running_locked();

// True when the kernel runs on the virtual clock (chm_time_now() is then
// not CLOCK_MONOTONIC).
bool clock_is_virtual();

// Park the calling task until word_granted(*word), or until `deadline` on
// the kernel's clock (chm_time_now(); UINT64_MAX: no limit; one already
// reached: -ETIMEDOUT at once unless the word is set). When the RTPU polls (idle_poll_ns) and has no other task ready,
// the task first spins on the word for up to that long, in its own context
// (preemptible), and parks only if no grant came. Returns 0 (word set), -ETIMEDOUT, -EINTR (a user signal) or
// -EPERM (not a task that can park: use a futex instead).
int remote_wait(std::uint32_t* word, std::uint64_t deadline);

// The value a waiter's word should start at, written before a granter can
// see it: kWordWatched when remote_wait will spin first (so a grant that
// comes before the spin begins rings nothing either), else 0.
std::uint32_t remote_wait_initial_word();

// Wake every parked task whose word is set. Mask held (the grant vector's
// handler), or from task context through remote_scan().
void remote_scan_locked();
void remote_scan();

// A word's value while its waiter's RTPU polls it in its idle loop: the
// granter's exchange that finds it knows the poll will see the grant, and
// rings no doorbell. Never a grant value. Set and cleared only on the
// waiter's own RTPU: by its idle loop around the poll (for parked tasks'
// words; no task runs meanwhile), or by the waiting task itself while it
// spins before it parks (remote_wait, when the RTPU polls and has nothing
// else to run).
inline constexpr std::uint32_t kWordWatched = UINT32_MAX;
inline bool word_granted(std::uint32_t v) { return v != 0 && v != kWordWatched; }

// True when some task waits on a word (mask held).
bool remote_waiting_locked();
// The idle poll's watch over those words (port::IdleWatch).
extern const port::IdleWatch kRemoteWatch;

}  // namespace chm::kernel
