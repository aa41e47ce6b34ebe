// Waiting on a word in shared memory: the kernel side of every backplane
// wait (remote semaphores, message queues, express-mail replies). A task
// parks until another process sets the word non-zero and rings this
// RTPU's doorbell with the grant vector; only the task waits, never the
// RTPU. Used by src/ipc/ (internal; the public calls are chm_rsem_*,
// chm_msgq_*).
#pragma once

#include <cstdint>

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

// Park the calling task until *word != 0, or `timeout_ns` passes (< 0: no
// limit). Returns 0 (word set), -ETIMEDOUT, -EINTR (a user signal) or
// -EPERM (not a task that can park: use a futex instead).
int remote_wait(const std::uint32_t* word, std::int64_t timeout_ns);

// Wake every parked task whose word is set. Mask held (the grant vector's
// handler), or from task context through remote_scan().
void remote_scan_locked();
void remote_scan();

}  // namespace chm::kernel
