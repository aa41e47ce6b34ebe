// Table 1, timer-driven rescheduling, on the real clock (the POSIX timer
// signal is this runtime's timer interrupt):
//  * timer_resched_noswitch, tick_cpu_locked: the time a timer event steals
//    from the running task. A periodic "spinner" reads the inline cycle
//    clock in a tight loop for 1.6 ms of every 2 ms window and records every
//    gap between two reads; four other periodic tasks are released at known
//    grid times inside the window. Each release is matched to the first gap
//    that starts after it (the signal, the kernel's tick work, the return);
//    stolen time = that gap − one loop iteration. Noswitch: the released
//    tasks have lower priority. Locked: the spinner holds chm_task_lock()
//    and the released tasks have higher priority, so the tick must record
//    the release and defer the switch to chm_task_unlock().
//  * timer_resched_switch: a priority-1 task spins writing the cycle clock
//    to memory; a priority-10 periodic task, at the first instruction of each
//    cycle, reads the clock: interrupted task's last instruction → released
//    task's first. Its lateness against the absolute release and the same
//    path on the virtual clock (no signal: the kernel alone) are stated.
#include <algorithm>
#include <array>

#include <sys/resource.h>

#include "kbench.hpp"

namespace chm::bench {
namespace {

using kb::ticks;

constexpr std::uint64_t kUs = 1000, kMs = 1000000;
constexpr std::uint64_t kWindow = 2 * kMs, kSpin = 1600 * kUs;
constexpr std::array<std::uint64_t, 4> kOffsets = {200 * kUs, 500 * kUs, 800 * kUs, 1100 * kUs};

struct Stolen {
    bool locked = false;
    int windows = 0, done = 0;
    std::vector<kb::SpinWindow> w;
    std::vector<std::uint64_t> release;  // the spinner's release of each window
    std::uint64_t misses = 0;
    volatile bool stop = false;
};

// Periodic tasks here report a late cycle and run on (no error signal).
chm_deadline_action count_miss(const chm_deadline_info_t*, void* arg) {
    ++*static_cast<std::uint64_t*>(arg);
    return CHM_DL_CONTINUE;
}

void spinner(void* p) {
    auto* a = static_cast<Stolen*>(p);
    const kb::TickClock& clk = kb::tick_clock();
    while (a->done < a->windows && !watchdog_fired()) {
        const std::size_t i = std::size_t(a->done++);
        kb::SpinWindow& w = a->w[i];
        a->release[i] = chm_task_cycle_release();
        w.mono0 = mono_ns();
        w.tick0 = ticks();
        const double left = double(a->release[i] + kSpin) - double(w.mono0);
        if (left > 0) {  // else released too late (the host ran something else)
            const std::uint64_t end = w.tick0 + clk.from_ns(left);
            if (a->locked) chm_task_lock();
            w.iters = kb::spin_gaps(end, clk.from_ns(150), &w.gaps, w.gaps.capacity());
            w.spin_ticks = ticks() - w.tick0;
            if (a->locked) chm_task_unlock();  // the released tasks run here
        }
        chm_task_wait_period();
    }
    a->stop = true;
}

void released(void* p) {
    auto* a = static_cast<Stolen*>(p);
    while (!a->stop) chm_task_wait_period();
}

struct StolenFigures {
    Stats st;  // per window: median stolen ns of its events; over windows
    int matched = 0, expected = 0, windows = 0;
    double other_per_window = 0;
    std::uint64_t misses = 0;
};

StolenFigures stolen(Session& s, bool locked) {
    kb::Kernel k({CHM_SCHED_FIXED, 1, 0});  // under MUF a periodic release would preempt the computing task
    kb::tick_clock();
    Stolen a;
    a.locked = locked;
    a.windows = s.quick() ? 41 : 301;
    a.w.resize(std::size_t(a.windows));
    a.release.resize(std::size_t(a.windows));
    for (kb::SpinWindow& w : a.w) w.gaps.reserve(64);
    const std::uint64_t start = (chm_time_now() / kMs + 5) * kMs;
    kb::TaskSpec sp;
    sp.priority = locked ? 1 : 10;
    sp.period_ns = kWindow;
    sp.start_ns = start;
    sp.on_deadline = count_miss;
    sp.on_deadline_arg = &a.misses;
    kb::spawn(spinner, &a, sp);
    for (std::uint64_t off : kOffsets) {
        kb::TaskSpec ev = sp;
        ev.priority = locked ? 10 : 1;
        ev.start_ns = start + off;
        kb::spawn(released, &a, ev);
    }
    k.run();

    StolenFigures f;
    std::vector<double> per_window;
    int other = 0;
    for (std::size_t i = 1; i < a.w.size(); ++i) {  // window 0: first entries, cold
        std::vector<std::uint64_t> events;
        for (std::uint64_t off : kOffsets) events.push_back(a.release[i] + off);
        std::vector<double> v;
        other += kb::match_gaps(a.w[i], events, &v, &f.expected);
        f.matched += int(v.size());
        if (!v.empty()) per_window.push_back(kb::stats_of(v).median);
    }
    if (per_window.empty()) throw std::runtime_error("no timer event was seen by the spinner");
    f.st = kb::stats_of(per_window);
    f.windows = int(per_window.size());
    f.other_per_window = double(other) / double(a.w.size() - 1);
    f.misses = a.misses;
    return f;
}

std::string stolen_config(Session& s, const StolenFigures& f, const char* what) {
    char b[240];
    std::snprintf(b, sizeof b,
                  "; %d of %d releases inside the spin matched; %.2f other gaps > 150 ns per "
                  "window (host, other interrupts); %llu deadline misses; median over %d windows "
                  "of each window's median",
                  f.matched, f.expected, f.other_per_window, (unsigned long long)f.misses,
                  f.windows);
    return kb::pinned(s) + ", FIXED policy, default config (cpu_accounting 1), real clock; " +
           what + "; 4 periodic tasks released per 2 ms window at known grid times, each matched "
                  "to the first gap in a " +
           kb::tick_clock().name + " read loop that starts after it; stolen = gap − one loop "
                                   "iteration; includes the host's timer interrupt and signal "
                                   "delivery (see peer_timer_signal_busy for that floor alone)" + b;
}

void noswitch_row(Session& s) {
    Session::pin(s.cpu(0));
    const StolenFigures f = stolen(s, false);
    s.emit("timer_resched_noswitch",
           stolen_config(s, f, "a priority-10 task computes; the releases are of priority-1 "
                               "tasks (the tick runs the scheduler, the running task stays)"),
           f.st.median, f.st.min, f.st.max);
    // The same figure beside the host's timer-signal floor (like for like:
    // a timer expiry that steals time from a computing thread).
    s.emit("timer_resched_noswitch_vs_floor",
           "timer_resched_noswitch's figure, beside peer_timer_signal_busy (a POSIX timer signal "
           "to a computing thread, measured the same way in the same run)",
           f.st.median, f.st.min, f.st.max);
}
CHM_BENCH_MEASUREMENT(noswitch_row, "timer_resched_noswitch", "timer_resched_noswitch_vs_floor");

void locked_row(Session& s) {
    Session::pin(s.cpu(0));
    const StolenFigures f = stolen(s, true);
    s.emit("tick_cpu_locked",
           stolen_config(s, f, "a priority-1 task computes holding chm_task_lock(); the releases "
                               "are of priority-10 tasks (the tick records them and defers the "
                               "switch to chm_task_unlock)"),
           f.st.median, f.st.min, f.st.max);
}
CHM_BENCH_MEASUREMENT(locked_row, "tick_cpu_locked");

// ---- timer reschedule with a switch
struct Switch {
    volatile std::uint64_t last = 0;
    volatile bool stop = false;
    volatile int done = 0;
    int cycles = 0;
    std::uint64_t start = 0, period = 0;
    std::uint64_t misses = 0;
    long invol = 0, vol = 0;
    std::vector<double> gap_ns, late_ns;
};

// Spins only from 300 us before each release until the released task has
// run: a thread that never sleeps is what Linux deschedules first on a busy
// machine, and that would be measured instead of the release.
void sw_spin(void* p) {
    auto* a = static_cast<Switch*>(p);
    const kb::TickClock& clk = kb::tick_clock();
    for (std::uint64_t k = 0; !a->stop; ++k) {
        const std::uint64_t r = a->start + k * a->period;
        chm_task_pause_until(r - 300 * kUs);
        const int seen = a->done;
        const std::uint64_t end = ticks() + clk.from_ns(double(a->period));
        while (a->done == seen && !a->stop) {
            const std::uint64_t t = ticks();
            a->last = t;
            if (t > end) break;  // missed it: next window
        }
    }
}

void sw_real(void* p) {
    auto* a = static_cast<Switch*>(p);
    const kb::TickClock& clk = kb::tick_clock();
    for (;;) {
        const std::uint64_t t = ticks();  // first instruction of the cycle
        const std::uint64_t now = mono_ns();
        a->gap_ns.push_back(clk.ns(t - a->last) - clk.pair_ns);
        a->late_ns.push_back(double(now) - double(chm_task_cycle_release()));
        a->done = a->done + 1;
        if (a->done >= a->cycles || watchdog_fired()) {
            a->stop = true;
            return;
        }
        chm_task_wait_period();
    }
}

// Virtual clock: the low task's chm_time_consume crosses the release.
void sw_virt_low(void* p) {
    auto* a = static_cast<Switch*>(p);
    while (!a->stop) {
        a->last = ticks();
        chm_time_consume(300 * kUs);
    }
}
void sw_virt_high(void* p) {
    auto* a = static_cast<Switch*>(p);
    const kb::TickClock& clk = kb::tick_clock();
    for (;;) {
        const std::uint64_t t = ticks();
        a->gap_ns.push_back(clk.ns(t - a->last) - clk.pair_ns);
        a->done = a->done + 1;
        if (a->done >= a->cycles) {
            a->stop = true;
            return;
        }
        chm_task_wait_period();
    }
}

// Median per run of `per` consecutive samples (the first two dropped:
// first entries), then median and min–max over runs.
Stats runs_of(const std::vector<double>& v, int per) {
    std::vector<double> runs;
    for (std::size_t i = 2; i + std::size_t(per) <= v.size(); i += std::size_t(per))
        runs.push_back(kb::stats_of({v.begin() + long(i), v.begin() + long(i) + per}).median);
    return kb::stats_of(runs);
}

void switch_row(Session& s) {
    Session::pin(s.cpu(0));
    kb::tick_clock();  // calibrated before any task runs
    const int per = s.quick() ? 10 : 20, nruns = s.quick() ? 21 : 101;
    Switch real;
    real.cycles = per * nruns + 2;
    real.gap_ns.reserve(std::size_t(real.cycles));
    real.late_ns.reserve(std::size_t(real.cycles));
    {
        kb::Kernel k({CHM_SCHED_FIXED, 1, 0});
        kb::TaskSpec hi;
        hi.priority = 10;
        hi.period_ns = real.period = 2 * kMs;
        hi.start_ns = real.start = (chm_time_now() / kMs + 5) * kMs;
        hi.on_deadline = count_miss;
        hi.on_deadline_arg = &real.misses;
        kb::spawn(sw_real, &real, hi);
        kb::spawn(sw_spin, &real, 1);
        rusage r0, r1;
        getrusage(RUSAGE_THREAD, &r0);
        k.run();
        getrusage(RUSAGE_THREAD, &r1);
        real.invol = r1.ru_nivcsw - r0.ru_nivcsw;
        real.vol = r1.ru_nvcsw - r0.ru_nvcsw;
    }
    Switch virt;
    virt.cycles = per * nruns + 2;
    virt.gap_ns.reserve(std::size_t(virt.cycles));
    {
        kb::Kernel k({CHM_SCHED_FIXED, 1, 0, 1});
        kb::TaskSpec hi;
        hi.priority = 10;
        hi.period_ns = kMs;
        hi.start_ns = kMs;
        hi.on_deadline = count_miss;
        hi.on_deadline_arg = &virt.misses;
        kb::spawn(sw_virt_high, &virt, hi);
        kb::spawn(sw_virt_low, &virt, 1);
        k.run();
    }
    const Stats st = runs_of(real.gap_ns, per);
    const Stats vst = runs_of(virt.gap_ns, per);
    std::vector<double> late(real.late_ns.begin() + 2, real.late_ns.end());
    std::sort(late.begin(), late.end());
    s.emit("timer_resched_switch",
           kb::pinned(s) + ", FIXED policy, default config, real clock; a priority-10 periodic task "
                           "released every 2 ms while a priority-1 task spins (from 300 us before each release) writing the " +
               kb::tick_clock().name +
               " to memory: spinner's last write → the released task's first instruction "
               "(timer signal, kernel tick, preemption trampoline with the full XSAVE image, "
               "switch); median over " + std::to_string(st.runs) + " runs of the median of " +
               std::to_string(per) + " releases; lateness of that first instruction against the "
               "absolute release (CLOCK_MONOTONIC, includes the host timer's own latency): p50 " +
               kb::fmt_ns(kb::percentile(late, 0.5)) + ", p99 " +
               kb::fmt_ns(kb::percentile(late, 0.99)) +
               "; the kernel's part alone on the virtual clock (chm_time_consume crossing the "
               "release → first instruction, no signal): " + kb::fmt_ns(vst.median) + "; " +
               std::to_string(real.misses) + " deadline misses; the thread was preempted by Linux " +
               std::to_string(real.invol) + " times (" + std::to_string(real.vol) + " sleeps)",
           st.median, st.min, st.max);
}
CHM_BENCH_MEASUREMENT(switch_row, "timer_resched_switch");

}  // namespace
}  // namespace chm::bench
