// The plain periodic loop a user would write without an RTOS: a periodic
// POSIX timer and sigwaitinfo at 1 kHz, on the calling thread (pinned by
// the caller). Used by the peer_sigwait_1khz_lateness_* rows and, in
// blocks alternating with the Chimera tasks, by
// release_lateness_p99_20tasks (predictability.cpp).
#pragma once

#include <cstdint>
#include <vector>

#include "../harness.hpp"

namespace chm::bench {

inline constexpr int kSigwaitWarmupPeriods = 20;

struct SigwaitRun {
    std::vector<double> late;  // ns after each period's release, every period
    std::uint64_t overrun = 0;  // periods served a period or more late
};

// `periods` periods after kSigwaitWarmupPeriods of warm-up, appended to *out.
void sigwait_periods(int periods, SigwaitRun* out);

}  // namespace chm::bench
