// CHM_HOT marks a function on the path every cycle of a periodic task or
// control module runs: release tick, switch, copy-in, copy-out, the wait
// for the next period. The compiler puts such functions in .text.hot.*,
// which the linker lays out together, so a cycle that starts cold after
// its task slept a period touches a few pages of code, not one per source
// file (each a TLB miss: under nested paging a walk of up to 24 memory
// reads). Measured by bench row module_cycle_cpu and its peer.
#pragma once

#define CHM_HOT __attribute__((hot))
