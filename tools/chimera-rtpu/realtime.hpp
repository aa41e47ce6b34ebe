// How chimera-rtpu asks the host OS for real-time treatment: a SCHED_FIFO
// priority, one CPU, memory locked. Applied before the RTPU joins, so every
// thread the process creates later (the backplane monitor) inherits them.
#pragma once

#include <string>

namespace chimera_rtpu {

struct HostRealtime {
    int fifo_priority = 0;     // 1..99: SCHED_FIFO at this priority; 0: leave as is
    int cpu = -1;              // >= 0: run only on this CPU
    bool lock_memory = false;  // mlockall: no page fault in a control loop
};

// Parse "--rt-priority" / "--cpu" values: "" when fine, else why not.
std::string parse_fifo_priority(const char* s, int* out);
std::string parse_cpu(const char* s, int* out);

// Apply them to the calling process (CPU, then memory, then priority): ""
// when done, else a message naming the option and what the OS said. An
// option that fails leaves the ones before it in force; the caller exits.
std::string apply(const HostRealtime& rt);

// After apply, before any thread exists (capabilities are per thread):
// give up every capability, keeping only CAP_IPC_LOCK while memory stays
// locked (MCL_FUTURE: later mappings, e.g. a loaded program, are locked
// too and would otherwise count against RLIMIT_MEMLOCK). Ambient
// capabilities go too, and the process is made dumpable again (a binary
// with file capabilities starts non-dumpable, which would hide its
// /proc/PID/maps from the peers that check its identity before a wake).
// "" when done, else what the OS said.
std::string drop_privileges(const HostRealtime& rt);

}  // namespace chimera_rtpu
