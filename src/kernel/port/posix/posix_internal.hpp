// State shared by the POSIX port's own files, not part of the contract.
#pragma once

#include <cstdint>

namespace chm::port {

// The timer handler bumps the doorbell's futex word when it records a
// pending tick, so an idle loop about to sleep on it returns at once.
void doorbell_bump_from_signal();

// The kernel thread's id (for directed signals); 0 before timer_init.
extern int g_kernel_tid;

// Register the main program's code as preemptible (once).
void preemptible_ranges_init();

}  // namespace chm::port
