// State shared by the POSIX port's own files, not part of the contract.
#pragma once

#include <cstdint>

namespace chm::port {

// Bumped by the timer handler and idle_wake(); idle sleeps on it.
extern std::uint32_t g_wake_seq;

// The kernel thread's id (for directed signals); 0 before timer_init.
extern int g_kernel_tid;

// Register the main program's code as preemptible (once).
void preemptible_ranges_init();

}  // namespace chm::port
