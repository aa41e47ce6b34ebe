// Peer of the timer rows: what a plain POSIX timer signal costs a thread
// that is computing, measured exactly as timer_resched_noswitch is (gaps in
// a cycle-clock read loop matched to the expiries). On a virtual machine
// this is mostly the host: the timer interrupt, its injection into the
// guest and the signal delivery; it is the floor under every timer row.
#include <signal.h>
#include <time.h>
#include <unistd.h>

#include "../kernel/kbench.hpp"

namespace chm::bench {
namespace {

void on_tick(int) {}

void timer_busy(Session& s) {
    Session::pin(s.cpu(0));
    const kb::TickClock& clk = kb::tick_clock();
    constexpr std::uint64_t kPeriod = 500000, kWindow = 2000000;
    const int sig = SIGRTMIN + 3;
    struct sigaction sa{}, old{};
    sa.sa_handler = on_tick;
    sigemptyset(&sa.sa_mask);
    sa.sa_flags = SA_RESTART;
    check(sigaction(sig, &sa, &old) == 0, "sigaction");
    sigevent sev{};
    sev.sigev_notify = SIGEV_THREAD_ID;
    sev.sigev_signo = sig;
    sev._sigev_un._tid = gettid();
    timer_t timer;
    check(timer_create(CLOCK_MONOTONIC, &sev, &timer) == 0, "timer_create");
    const int windows = s.quick() ? 41 : 301;
    const std::uint64_t start = (mono_ns() / kWindow + 2) * kWindow;
    itimerspec its{};
    its.it_value = {time_t((start + 200000) / 1000000000u), long((start + 200000) % 1000000000u)};
    its.it_interval = {0, long(kPeriod)};
    timer_settime(timer, TIMER_ABSTIME, &its, nullptr);
    while (mono_ns() < start) {
    }
    std::vector<double> per_window;
    int expected = 0, matched = 0, other = 0;
    kb::SpinWindow w;
    w.gaps.reserve(64);
    for (int i = 0; i < windows && !watchdog_fired(); ++i) {
        const std::uint64_t ws = start + std::uint64_t(i) * kWindow;
        w.gaps.clear();
        w.mono0 = mono_ns();
        w.tick0 = kb::ticks();
        const double left = double(ws + kWindow) - double(w.mono0);
        if (left <= 0) continue;
        w.iters = kb::spin_gaps(w.tick0 + clk.from_ns(left), clk.from_ns(150), &w.gaps, 64);
        w.spin_ticks = kb::ticks() - w.tick0;
        std::vector<std::uint64_t> events;
        for (std::uint64_t e = ws + 200000; e < ws + kWindow; e += kPeriod) events.push_back(e);
        std::vector<double> v;
        other += kb::match_gaps(w, events, &v, &expected);
        matched += int(v.size());
        if (i > 0 && !v.empty()) per_window.push_back(kb::stats_of(v).median);
    }
    its = {};
    timer_settime(timer, 0, &its, nullptr);
    timer_delete(timer);
    sigaction(sig, &old, nullptr);
    if (per_window.empty()) throw std::runtime_error("no timer expiry was seen");
    const Stats st = kb::stats_of(per_window);
    char b[200];
    std::snprintf(b, sizeof b,
                  "; %d of %d expiries matched, %.2f other gaps per window; median over %d "
                  "windows of each window's median",
                  matched, expected, double(other) / windows, st.runs);
    s.emit("peer_timer_signal_busy",
           "pinned " + s.cpu_name(0) + ", SCHED_OTHER, periodic POSIX timer (500 us, "
           "SIGEV_THREAD_ID to this thread, empty handler) while the thread spins reading the " +
               clk.name + "; stolen = the gap after each expiry − one loop iteration" + b,
           st.median, st.min, st.max);
}
CHM_BENCH_MEASUREMENT(timer_busy, "peer_timer_signal_busy");

}  // namespace
}  // namespace chm::bench
