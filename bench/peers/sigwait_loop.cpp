// Peer: the plain periodic loop a user would write without an RTOS, a
// periodic POSIX timer and sigwaitinfo at 1 kHz. Its release lateness (how
// long after each period's start the loop runs) is the baseline of the
// Chimera periodic-task lateness rows.
#include <signal.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "sigwait_loop.hpp"

namespace chm::bench {
namespace {

constexpr std::uint64_t kPeriodNs = 1000000;  // 1 kHz
constexpr int kWarmupPeriods = kSigwaitWarmupPeriods;

double percentile(const std::vector<double>& sorted, double q) {
    const std::size_t rank = std::size_t(std::ceil(q * double(sorted.size())));
    return sorted[std::min(sorted.size(), std::max<std::size_t>(rank, 1)) - 1];
}

timespec to_ts(std::uint64_t ns) {
    return {time_t(ns / 1000000000u), long(ns % 1000000000u)};
}

}  // namespace

void sigwait_periods(int periods, SigwaitRun* out) {
    const int sig = SIGRTMIN + 1;
    sigset_t set, old_mask;
    sigemptyset(&set);
    sigaddset(&set, sig);
    check(pthread_sigmask(SIG_BLOCK, &set, &old_mask) == 0, "pthread_sigmask");

    sigevent sev{};
    sev.sigev_notify = SIGEV_THREAD_ID;
    sev.sigev_signo = sig;
    sev._sigev_un._tid = gettid();  // glibc 2.36 lacks sigev_notify_thread_id
    timer_t timer;
    check(timer_create(CLOCK_MONOTONIC, &sev, &timer) == 0, "timer_create");
    // Absolute, periodic: expiries stay on the grid start + k * period, so
    // lateness never accumulates into drift.
    const std::uint64_t start = (mono_ns() / kPeriodNs + 2) * kPeriodNs;
    itimerspec its{};
    its.it_value = to_ts(start);
    its.it_interval = to_ts(kPeriodNs);

    std::vector<double>& late = out->late;
    late.reserve(late.size() + std::size_t(periods));
    std::uint64_t next = 0;
    auto cleanup = [&] {
        timer_delete(timer);
        siginfo_t info;
        const timespec zero{0, 0};
        while (sigtimedwait(&set, &info, &zero) == sig) {
        }
        pthread_sigmask(SIG_SETMASK, &old_mask, nullptr);
    };
    try {
        check(timer_settime(timer, TIMER_ABSTIME, &its, nullptr) == 0, "timer_settime");
        for (int i = 0; i < periods + kWarmupPeriods; ++i) {
            siginfo_t info;
            while (sigwaitinfo(&set, &info) != sig) eintr_or_fail("sigwaitinfo");
            const std::uint64_t now = mono_ns();
            // One signal stands for 1 + si_overrun expiries; the loop now
            // serves the latest of them. Every period counts, as in the
            // Chimera rows: each earlier one (missed: its work can start no
            // sooner than now) is sampled with its own lateness, now minus
            // its release, a period or more.
            const std::uint64_t k = next + std::uint64_t(info.si_overrun);
            if (i >= kWarmupPeriods) {
                for (std::uint64_t j = next; j <= k; ++j)
                    late.push_back(double(now) - double(start + j * kPeriodNs));
                out->overrun += std::uint64_t(info.si_overrun);
            }
            next = k + 1;
        }
    } catch (...) {
        cleanup();
        throw;
    }
    cleanup();
}

namespace {

void sigwait_lateness(Session& s) {
    Session::pin(s.cpu(0));
    const int periods = s.quick() ? 500 : 10000;
    SigwaitRun run;
    sigwait_periods(periods, &run);
    std::vector<double>& late = run.late;
    const std::uint64_t missed = run.overrun;

    s.write_samples("peer_sigwait_1khz_lateness", late);
    std::sort(late.begin(), late.end());
    const std::string config = std::to_string(periods) + " periods after " +
                               std::to_string(kWarmupPeriods) + " warm-up, pinned " + s.cpu_name(0) +
                               ", SCHED_OTHER, absolute periodic timer to this thread; " +
                               std::to_string(late.size()) + " periods sampled, of which " +
                               std::to_string(missed) +
                               " overrun (served a period or more late, sampled with that lateness)";
    s.emit("peer_sigwait_1khz_lateness_p50", config, percentile(late, 0.50));
    s.emit("peer_sigwait_1khz_lateness_p99", config, percentile(late, 0.99));
    s.emit("peer_sigwait_1khz_lateness_p999", config, percentile(late, 0.999));
    s.emit("peer_sigwait_1khz_lateness_max", config, late.back());
}
CHM_BENCH_MEASUREMENT(sigwait_lateness, "peer_sigwait_1khz_lateness_p50",
                      "peer_sigwait_1khz_lateness_p99", "peer_sigwait_1khz_lateness_p999",
                      "peer_sigwait_1khz_lateness_max");

}  // namespace
}  // namespace chm::bench
