// A periodic task body for "the RTPU kept running" checks: it counts its
// cycles and the longest gap between two of them until `stop` is set. A
// blocked RTPU shows one gap as long as the block (then a burst of late
// cycles), which a cycle count alone would hide.
#pragma once

#include <cstdint>

#include "chimera/chimera.h"

namespace chm::test {

struct GapTicker {
    static inline volatile bool stop = false;
    static inline volatile int cycles = 0;
    static inline volatile uint64_t max_gap = 0;  // ns

    static void reset() {
        stop = false;
        cycles = 0;
        max_gap = 0;
    }
    // Spawn with a period; its argument is unused.
    static void body(void*) {
        uint64_t last = chm_time_now();
        while (!stop) {
            const uint64_t now = chm_time_now();
            if (now - last > max_gap) max_gap = now - last;
            last = now;
            cycles = cycles + 1;
            chm_task_wait_period();
        }
    }
};

}  // namespace chm::test
