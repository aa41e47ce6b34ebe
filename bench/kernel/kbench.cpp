// The kernel rows' shared helpers (see kbench.hpp).
#include "kbench.hpp"
#include "port.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace chm::bench::kb {

namespace {
std::exception_ptr g_failure;
}

Kernel::Kernel(const KernelOpts& o) {
    chm_kernel_config_t cfg;
    chm_kernel_config_init(&cfg);
    cfg.policy = o.policy;
    cfg.cpu_accounting = o.cpu_accounting;
    cfg.quantum_ns = o.quantum_ns;
    cfg.virtual_clock = o.virtual_clock;
    cfg.default_stack = o.default_stack;
    g_failure = nullptr;
    if (const int e = chm_kernel_init(&cfg))
        throw std::runtime_error("chm_kernel_init: error " + std::to_string(e));
}

Kernel::~Kernel() { chm_kernel_fini(); }

void Kernel::run_and_rethrow() {
    const int r = chm_kernel_run();
    if (g_failure) {
        std::exception_ptr e = g_failure;
        g_failure = nullptr;
        std::rethrow_exception(e);
    }
    if (r != 0) throw std::runtime_error("chm_kernel_run returned " + std::to_string(r));
}

void Kernel::forget_failure() { g_failure = nullptr; }

void Kernel::store_current_exception() { store_failure(std::current_exception()); }

void Kernel::store_failure(std::exception_ptr e) {
    if (!g_failure) g_failure = e;
}

void Kernel::stop_failed() { chm_kernel_stop(-1); }

chm_tid_t spawn(void (*fn)(void*), void* arg, const TaskSpec& t) {
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = t.name;
    a.priority = t.priority;
    a.period_ns = t.period_ns;
    a.start_ns = t.start_ns;
    a.wcet_ns = t.wcet_ns;
    a.deadline_ns = t.deadline_ns;
    a.critical = t.critical;
    a.stack_size = t.stack;
    a.on_deadline = t.on_deadline;
    a.on_deadline_arg = t.on_deadline_arg;
    chm_tid_t id = CHM_TID_NONE;
    if (const int e = chm_task_spawn(&id, fn, arg, &a))
        throw std::runtime_error("chm_task_spawn: error " + std::to_string(e));
    return id;
}

chm_tid_t spawn(void (*fn)(void*), void* arg, int priority) {
    TaskSpec t;
    t.priority = priority;
    return spawn(fn, arg, t);
}

namespace {
void run_fn(void* p) {
    guarded([p] { (*static_cast<std::function<void()>*>(p))(); });
}
}  // namespace

chm_tid_t spawn_fn(std::function<void()>* fn, const TaskSpec& t) { return spawn(run_fn, fn, t); }

const TickClock& tick_clock() {
    static const TickClock c = [] {
        TickClock k;
#if defined(__x86_64__)
        k.name = "TSC";
#elif defined(__aarch64__)
        k.name = "CNTVCT";
#else
        k.name = "CLOCK_MONOTONIC";
#endif
        const std::uint64_t m0 = mono_ns(), c0 = ticks();
        while (mono_ns() - m0 < 25000000) {
        }
        const std::uint64_t m1 = mono_ns(), c1 = ticks();
        k.ns_per_tick = double(m1 - m0) / double(c1 - c0);
        std::vector<double> pair;
        for (int i = 0; i < 2001; ++i) {
            const std::uint64_t a = ticks(), b = ticks();
            pair.push_back(double(b - a) * k.ns_per_tick);
        }
        std::sort(pair.begin(), pair.end());
        k.pair_ns = pair[pair.size() / 2];
        return k;
    }();
    return c;
}

std::uint64_t spin_gaps(std::uint64_t end, std::uint64_t thresh, std::vector<Gap>* out,
                        std::size_t cap) {
    std::uint64_t iters = 0, prev = ticks();
    for (;;) {
        const std::uint64_t t = ticks();
        ++iters;
        if (t - prev > thresh && out->size() < cap) out->push_back(Gap{prev, t - prev});
        prev = t;
        if (t >= end) return iters;
    }
}

int match_gaps(const SpinWindow& w, const std::vector<std::uint64_t>& events,
               std::vector<double>* stolen, int* expected) {
    const TickClock& clk = tick_clock();
    if (!w.iters) return int(w.gaps.size());
    double gaps_ns = 0;
    for (const Gap& g : w.gaps) gaps_ns += clk.ns(g.len);
    const double iter = (clk.ns(w.spin_ticks) - gaps_ns) / double(w.iters);
    const double end_tick = double(w.tick0 + w.spin_ticks);
    std::vector<bool> used(w.gaps.size(), false);
    for (std::uint64_t ev : events) {
        const double r_ns = double(ev) - double(w.mono0);
        const double r_tick = double(w.tick0) + r_ns / clk.ns_per_tick;
        if (r_ns < 0 || r_tick > end_tick) continue;  // not inside the spin
        ++*expected;
        for (std::size_t g = 0; g < w.gaps.size(); ++g) {
            const double at = double(w.gaps[g].at);
            if (used[g] || at + double(w.gaps[g].len) < r_tick) continue;
            if (at > r_tick + 300e3 / clk.ns_per_tick) break;
            used[g] = true;
            stolen->push_back(clk.ns(w.gaps[g].len) - iter);
            break;
        }
    }
    int other = 0;
    for (bool u : used) other += !u;
    return other;
}

Stats stats_of(std::vector<double> v) {
    Stats s;
    if (v.empty()) return s;
    std::sort(v.begin(), v.end());
    const std::size_t mid = v.size() / 2;
    s.median = v.size() % 2 ? v[mid] : (v[mid - 1] + v[mid]) / 2;
    s.min = v.front();
    s.max = v.back();
    s.runs = int(v.size());
    return s;
}

double percentile(std::vector<double>& sorted, double q) {
    if (sorted.empty()) return kNull;
    const std::size_t rank = std::size_t(std::ceil(q * double(sorted.size())));
    return sorted[std::min(sorted.size(), std::max<std::size_t>(rank, 1)) - 1];
}

std::string fmt_ns(double ns) {
    char b[48];
    if (std::isnan(ns)) return "-";
    if (std::fabs(ns) < 1000) std::snprintf(b, sizeof b, "%.1f ns", ns);
    else if (std::fabs(ns) < 1e6) std::snprintf(b, sizeof b, "%.2f us", ns / 1e3);
    else std::snprintf(b, sizeof b, "%.2f ms", ns / 1e6);
    return b;
}

std::string pinned(Session& s) { return "pinned " + s.cpu_name(0) + ", one RTPU"; }

std::string clock_used() {
    return chm::port::clock_extrapolates() ? "the kernel's clock extrapolated with the cycle counter"
                                           : "the kernel's clock read from CLOCK_MONOTONIC (vDSO)";
}

}  // namespace chm::bench::kb
