// Predictability on the real clock: release lateness of 1 kHz periodic
// tasks (1, 20, 200 on one RTPU), the CPU an idle RTPU uses, and the CPU
// share left to control tasks running at 1000 Hz (the paper's > 90 %).
// Default kernel config (MUF, 1 ms quantum, cpu_accounting 1) unless said.
#include <time.h>

#include <algorithm>
#include <cstdio>
#include <stdexcept>

#include "kbench.hpp"
#include "../peers/sigwait_loop.hpp"

namespace chm::bench {
namespace {

constexpr std::uint64_t kMs = 1000000;
constexpr int kWarmup = 20;

chm_deadline_action count_miss(const chm_deadline_info_t*, void* arg) {
    ++*static_cast<std::uint64_t*>(arg);
    return CHM_DL_CONTINUE;
}

double thread_cpu_ns() {
    timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return double(ts.tv_sec) * 1e9 + double(ts.tv_nsec);
}

// ---- release lateness: every task records, at the first instruction of
// each cycle, now − chm_task_cycle_release(). All tasks share one release
// grid (same phase), so with N tasks the last one runs after the other N-1.
struct Lateness {
    int periods = 0;
    std::vector<float> ns;  // [task * periods + cycle]
    std::uint64_t misses = 0;
};
struct LateTask {
    Lateness* l;
    int index;
};
void late_body(void* p) {
    auto* t = static_cast<LateTask*>(p);
    Lateness* l = t->l;
    for (int c = 0; c < l->periods + kWarmup; ++c) {
        const std::uint64_t late = chm_time_now() - chm_task_cycle_release();
        if (c >= kWarmup) l->ns[std::size_t(t->index) * std::size_t(l->periods) + std::size_t(c - kWarmup)] = float(late);
        if (watchdog_fired()) return;
        chm_task_wait_period();
    }
}

// One RTPU with `tasks` tasks for `periods` periods after kWarmup; every
// cycle's lateness appended to *all, misses added to *misses.
void lateness_block(int tasks, int periods, std::vector<double>* all, std::uint64_t* misses) {
    Lateness l;
    l.periods = periods;
    l.ns.assign(std::size_t(tasks) * std::size_t(l.periods), 0.f);
    std::vector<LateTask> args(static_cast<std::size_t>(tasks));
    {
        kb::Kernel k({CHM_SCHED_MUF, 1, 1000000});
        const std::uint64_t start = (chm_time_now() / kMs + 10) * kMs;
        for (int i = 0; i < tasks; ++i) {
            args[std::size_t(i)] = {&l, i};
            kb::TaskSpec t;
            t.period_ns = kMs;
            t.wcet_ns = 1000;
            t.start_ns = start;
            t.stack = 16 * 1024;
            t.on_deadline = count_miss;
            t.on_deadline_arg = &l.misses;
            kb::spawn(late_body, &args[std::size_t(i)], t);
        }
        k.run();
    }
    all->insert(all->end(), l.ns.begin(), l.ns.end());
    *misses += l.misses;
}

std::size_t count_overrun(const std::vector<double>& v) {
    std::size_t overrun = 0;
    for (double x : v)
        if (x >= double(kMs)) ++overrun;
    return overrun;
}

// The histogram file: at most 200,000 samples, evenly strided.
void write_strided(Session& s, const char* row, const std::vector<double>& v) {
    const std::size_t stride = std::max<std::size_t>(1, v.size() / 200000);
    std::vector<double> sample;
    for (std::size_t i = 0; i < v.size(); i += stride) sample.push_back(v[i]);
    s.write_samples(row, sample);
}

std::string lateness_config(Session& s, int tasks, const std::string& blocks, std::vector<double>& v,
                            std::size_t overrun, std::uint64_t misses) {
    char b[900];
    std::snprintf(b, sizeof b,
                  "%s, default config (MUF, cpu_accounting 1), real clock; %d periodic task%s at "
                  "1 kHz, same release grid, empty cycles (16 KiB stacks); lateness = "
                  "chm_time_now() − chm_task_cycle_release() at each cycle's first instruction; "
                  "%s, every cycle sampled (%zu): p50 %s, p99 %s, p99.9 %s, "
                  "max %s; %zu cycles began >= 1 period late (counted, in p99 and max); "
                  "%llu deadline misses; min – max = least and greatest lateness of any cycle",
                  kb::pinned(s).c_str(), tasks, tasks == 1 ? "" : "s", blocks.c_str(), v.size(),
                  kb::fmt_ns(kb::percentile(v, 0.5)).c_str(), kb::fmt_ns(kb::percentile(v, 0.99)).c_str(),
                  kb::fmt_ns(kb::percentile(v, 0.999)).c_str(), kb::fmt_ns(v.back()).c_str(), overrun,
                  (unsigned long long)misses);
    return b;
}

void lateness(Session& s, int tasks, const char* row, int full_periods) {
    Session::pin(s.cpu(0));
    const int periods = s.quick() ? 300 : full_periods;
    std::vector<double> v;
    std::uint64_t misses = 0;
    lateness_block(tasks, periods, &v, &misses);
    // Every cycle counts. A cycle that began a whole period or more after
    // its release (it ran when its successor was already due) is a late
    // cycle like any other: sampled with its lateness, counted apart, and in
    // the max.
    if (v.empty()) throw std::runtime_error("no cycle ran");
    write_strided(s, row, v);
    const std::size_t overrun = count_overrun(v);
    std::sort(v.begin(), v.end());
    const std::string blocks = std::to_string(periods) + " periods after " + std::to_string(kWarmup) + " warm-up";
    s.emit(row, lateness_config(s, tasks, blocks, v, overrun, misses), kb::percentile(v, 0.99), v.front(),
           v.back());
}

// The target row: the host's timer latency moves with the host's load over
// seconds, so the 20 tasks and their peer (the plain sigwaitinfo loop) run
// in alternating blocks of 1,000 periods, ten each, and each side's p99 is
// taken over all its blocks: a slow stretch of the host falls on both
// rather than on whichever ran through it.
void lateness_20_alternating(Session& s) {
    Session::pin(s.cpu(0));
    const int blocks = s.quick() ? 1 : 10;
    const int periods = s.quick() ? 300 : 1000;
    std::vector<double> v;
    std::uint64_t misses = 0;
    SigwaitRun peer;
    for (int b = 0; b < blocks; ++b) {
        lateness_block(20, periods, &v, &misses);
        sigwait_periods(periods, &peer);
    }
    if (v.empty() || peer.late.empty()) throw std::runtime_error("no cycle ran");
    const char* row = "release_lateness_p99_20tasks";
    write_strided(s, row, v);
    const std::size_t overrun = count_overrun(v);
    std::sort(v.begin(), v.end());
    std::sort(peer.late.begin(), peer.late.end());
    const std::string how = std::to_string(blocks) + " blocks of " + std::to_string(periods) + " periods (each after " +
                            std::to_string(kWarmup) +
                            " warm-up), alternating with as many blocks of "
                            "peer_sigwait_1khz_lateness_p99_alternating";
    s.emit(row, lateness_config(s, 20, how, v, overrun, misses), kb::percentile(v, 0.99), v.front(), v.back());
    s.emit("peer_sigwait_1khz_lateness_p99_alternating",
           std::to_string(blocks) + " blocks of " + std::to_string(periods) + " periods after " +
               std::to_string(kSigwaitWarmupPeriods) + " warm-up, alternating with release_lateness_p99_20tasks' "
               "blocks, pinned " + s.cpu_name(0) + ", SCHED_OTHER, absolute periodic timer to this thread; " +
               std::to_string(peer.late.size()) + " periods sampled, " + std::to_string(peer.overrun) +
               " overrun (sampled with that lateness); p50 " + kb::fmt_ns(kb::percentile(peer.late, 0.5)),
           kb::percentile(peer.late, 0.99), peer.late.front(), peer.late.back());
}

void lateness_1(Session& s) { lateness(s, 1, "release_lateness_p99_1task", 10000); }
void lateness_200(Session& s) { lateness(s, 200, "release_lateness_p99_200tasks", 5000); }
CHM_BENCH_MEASUREMENT(lateness_1, "release_lateness_p99_1task");
CHM_BENCH_MEASUREMENT(lateness_20_alternating, "release_lateness_p99_20tasks",
                      "peer_sigwait_1khz_lateness_p99_alternating");
CHM_BENCH_MEASUREMENT(lateness_200, "release_lateness_p99_200tasks");

// ---- idle RTPU: CPU time of the kernel thread (it runs every task and
// the idle loop) over wall time, while nothing is ready.
struct Idle {
    double window_ns = 0, cpu = 0, wall = 0;
};
void idle_paused(void* p) {
    auto* a = static_cast<Idle*>(p);
    const double c0 = thread_cpu_ns(), w0 = double(mono_ns());
    chm_task_pause_until(chm_time_now() + std::uint64_t(a->window_ns));
    a->cpu = thread_cpu_ns() - c0;
    a->wall = double(mono_ns()) - w0;
}
struct IdlePeriodic {
    Idle* a;
    std::uint64_t end = 0;
    double c0 = 0, w0 = 0;
};
void idle_10hz(void* p) {
    auto* t = static_cast<IdlePeriodic*>(p);
    t->c0 = thread_cpu_ns();
    t->w0 = double(mono_ns());
    while (chm_time_now() < t->end) chm_task_wait_period();
    t->a->cpu = thread_cpu_ns() - t->c0;
    t->a->wall = double(mono_ns()) - t->w0;
}

void idle_row(Session& s) {
    Session::pin(s.cpu(0));
    const double window = s.quick() ? 0.5e9 : 3e9;
    Idle none{window};
    {
        kb::Kernel k({CHM_SCHED_MUF, 1, 1000000});
        kb::spawn(idle_paused, &none, {});
        k.run();
    }
    Idle per{window};
    IdlePeriodic ip{&per};
    {
        kb::Kernel k({CHM_SCHED_MUF, 1, 1000000});
        ip.end = chm_time_now() + std::uint64_t(window);
        kb::TaskSpec t;
        t.period_ns = 100 * kMs;
        kb::spawn(idle_10hz, &ip, t);
        k.run();
    }
    const double pct_none = 100.0 * none.cpu / none.wall, pct_per = 100.0 * per.cpu / per.wall;
    char b[300];
    std::snprintf(b, sizeof b,
                  "%s, default config; CLOCK_THREAD_CPUTIME_ID of the kernel thread over %.1f s of "
                  "wall time; value: only a 10 Hz periodic task with an empty cycle; with nothing "
                  "ready at all (one task paused): %.4f %%",
                  kb::pinned(s).c_str(), window / 1e9, pct_none);
    s.emit("idle_rtpu_cpu", b, pct_per);
}
CHM_BENCH_MEASUREMENT(idle_row, "idle_rtpu_cpu");

// ---- CPU share left to 1 kHz control tasks. All application work is the
// same loop (`work`), counted in iterations: a background task (aperiodic:
// least urgent under MUF) runs it whenever nothing else is ready, and N
// control tasks run K iterations per 1 ms cycle. The rate r0 (iterations
// per CPU ns) is measured with the background alone, same kernel. Share
// left to the application = iterations done / (r0 × CPU time of the
// thread), i.e. 1 − (kernel + switch + cache overhead) / CPU time.
constexpr int kControl = 10;
constexpr std::uint64_t kChunk = 1000;

__attribute__((noinline)) std::uint64_t work(std::uint64_t x, std::uint64_t n) {
    for (std::uint64_t i = 0; i < n; ++i) x = x * 6364136223846793005ull + 1442695040888963407ull;
    return x;
}

struct Share {
    std::uint64_t iters_per_cycle = 0, window_ticks = 0, end_ns = 0;
    volatile bool stop = false;
    volatile bool measuring = false;
    std::uint64_t bg_iters = 0, ctl_cycles = 0, misses = 0;
    double cpu = 0;
    volatile std::uint64_t sink = 0;
};
void share_bg(void* p) {
    auto* a = static_cast<Share*>(p);
    std::uint64_t x = 1;
    x = work(x, kChunk * 100);  // warm
    const double c0 = thread_cpu_ns();
    const std::uint64_t end = kb::ticks() + a->window_ticks;
    a->measuring = true;
    std::uint64_t n = 0;
    while (kb::ticks() < end) {
        x = work(x, kChunk);
        n += kChunk;
    }
    a->measuring = false;
    a->cpu = thread_cpu_ns() - c0;
    a->bg_iters = n;
    a->sink = x;
    a->stop = true;
}
void share_ctl(void* p) {
    auto* a = static_cast<Share*>(p);
    std::uint64_t x = 7;
    // The end is a time, not a flag the background sets: on an overloaded
    // host the background may never run again.
    while (!a->stop && chm_time_now() < a->end_ns) {
        x = work(x, a->iters_per_cycle);
        if (a->measuring) ++a->ctl_cycles;
        chm_task_wait_period();
    }
    a->sink = x;
}

Share share_run(std::uint64_t window_ticks, int control, std::uint64_t k_iters) {
    Share a;
    a.window_ticks = window_ticks;
    a.iters_per_cycle = k_iters;
    kb::Kernel k({CHM_SCHED_MUF, 1, 1000000});
    const std::uint64_t start = (chm_time_now() / kMs + 2) * kMs;
    a.end_ns = start + std::uint64_t(kb::tick_clock().ns(window_ticks)) + 100 * kMs;
    for (int i = 0; i < control; ++i) {
        kb::TaskSpec t;
        t.period_ns = kMs;
        t.wcet_ns = 200000;
        t.start_ns = start;
        t.on_deadline = count_miss;
        t.on_deadline_arg = &a.misses;
        kb::spawn(share_ctl, &a, t);
    }
    kb::spawn(share_bg, &a, {});
    k.run();
    return a;
}

void control_share_row(Session& s) {
    Session::pin(s.cpu(0));
    const kb::TickClock& clk = kb::tick_clock();
    const double window = s.quick() ? 0.3e9 : 2e9;
    const int reps = s.quick() ? 1 : 3;
    // Size K so the control tasks' work is ~30 % of the CPU: 30 us per task-cycle.
    const Share cal = share_run(clk.from_ns(0.1e9), 0, 0);
    const double r_cal = double(cal.bg_iters) / cal.cpu;
    const std::uint64_t k_iters = std::uint64_t(30000.0 * r_cal);
    std::vector<double> shares, overhead_us;
    for (int r = 0; r < reps; ++r) {
        const Share base = share_run(clk.from_ns(window), 0, 0);
        const double r0 = double(base.bg_iters) / base.cpu;
        const Share load = share_run(clk.from_ns(window), kControl, k_iters);
        const double useful = double(load.bg_iters) + double(load.ctl_cycles) * double(k_iters);
        const double share = useful / (r0 * load.cpu);
        shares.push_back(100.0 * share);
        if (load.ctl_cycles)
            overhead_us.push_back((1 - share) * load.cpu / double(load.ctl_cycles) * kControl / 1e3);
    }
    const Stats st = kb::stats_of(shares);
    const Stats ov = kb::stats_of(overhead_us);
    char b[700];
    std::snprintf(b, sizeof b,
                  "%s, default config (MUF, cpu_accounting 1), real clock; %d control tasks at "
                  "1 kHz (same phase), each running a fixed loop of %llu iterations per cycle "
                  "(~%.0f us, ~%.0f %% of the CPU together) and a background task counting the "
                  "same loop; share = iterations done / (iterations per CPU-ns with the background "
                  "alone × CPU time of the kernel thread): 1 − the kernel's, switches' and cache "
                  "overhead; kernel overhead per 1 ms tick of %d releases: %.1f us; median of %d "
                  "alternating runs of %.1f s",
                  kb::pinned(s).c_str(), kControl, (unsigned long long)k_iters,
                  double(k_iters) / r_cal / 1e3, 100.0 * kControl * double(k_iters) / r_cal / 1e6,
                  kControl, ov.median, reps, window / 1e9);
    s.emit("control_cpu_share_1khz", b, st.median, st.min, st.max);
}
CHM_BENCH_MEASUREMENT(control_share_row, "control_cpu_share_1khz");

}  // namespace
}  // namespace chm::bench
