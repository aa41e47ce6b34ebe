// The measurement method shared by every row: calibrate the iteration count
// so one run lasts about Options::run_ns, warm up, repeat, report the median
// with the min and max over the runs. Also the watchdog and CPU pinning.
#include "harness.hpp"

#include <sched.h>
#include <signal.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <stdexcept>

#include "catalog.hpp"
#include "runner.hpp"

namespace chm::bench {

std::uint64_t mono_ns() {
    timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return std::uint64_t(ts.tv_sec) * 1000000000u + std::uint64_t(ts.tv_nsec);
}

// ------------------------------------------------------------------ watchdog

namespace {

volatile sig_atomic_t g_watchdog_fired = 0;
volatile sig_atomic_t g_child_died = 0;
timer_t g_watchdog_timer;
bool g_watchdog_ready = false;

// The signal's only job is to interrupt a blocking call (no SA_RESTART).
void on_watchdog(int) { g_watchdog_fired = 1; }

void on_child(int) { g_child_died = 1; }

int watchdog_signal() { return SIGRTMAX; }

}  // namespace

bool watchdog_fired() { return g_watchdog_fired != 0; }
void clear_child_died() { g_child_died = 0; }

const char* abort_reason() {
    if (g_watchdog_fired) return "timed out (watchdog)";
    if (g_child_died) return "the peer process exited";
    return nullptr;
}

void watchdog_init() {
    struct sigaction sa {};
    sa.sa_handler = on_watchdog;
    sigemptyset(&sa.sa_mask);
    sa.sa_flags = 0;  // no SA_RESTART: blocked system calls return EINTR
    if (sigaction(watchdog_signal(), &sa, nullptr) != 0) fail_errno("sigaction(watchdog)");
    // A peer process that dies interrupts the parent's wait the same way.
    sa.sa_handler = on_child;
    if (sigaction(SIGCHLD, &sa, nullptr) != 0) fail_errno("sigaction(SIGCHLD)");
    // Directed at this (the measuring) thread, never at a helper thread.
    sigevent sev {};
    sev.sigev_notify = SIGEV_THREAD_ID;
    sev.sigev_signo = watchdog_signal();
    sev._sigev_un._tid = gettid();  // glibc 2.36 lacks sigev_notify_thread_id
    if (timer_create(CLOCK_MONOTONIC, &sev, &g_watchdog_timer) != 0) fail_errno("timer_create(watchdog)");
    g_watchdog_ready = true;
}

void watchdog_arm(double seconds) {
    g_watchdog_fired = 0;
    g_child_died = 0;
    if (!g_watchdog_ready) return;
    itimerspec its {};
    its.it_value.tv_sec = time_t(seconds);
    its.it_value.tv_nsec = long((seconds - double(its.it_value.tv_sec)) * 1e9);
    // Once fired, keep interrupting every 100 ms so a call that retries
    // EINTR on its own cannot hold the measurement forever.
    its.it_interval.tv_nsec = 100000000;
    timer_settime(g_watchdog_timer, 0, &its, nullptr);
}

void watchdog_disarm() {
    if (!g_watchdog_ready) return;
    itimerspec its {};
    timer_settime(g_watchdog_timer, 0, &its, nullptr);
    g_watchdog_fired = 0;
}

[[noreturn]] void fail_errno(const std::string& what, int err) {
    if (err == EINTR && abort_reason())
        throw std::runtime_error(what + ": " + abort_reason());
    throw std::runtime_error(what + ": " + std::strerror(err));
}

// ------------------------------------------------------------------ registry

std::vector<Measurement>& registry() {
    static std::vector<Measurement> r;
    return r;
}

Registrar::Registrar(MeasureFn fn, const char* fn_name, std::initializer_list<const char*> rows) {
    Measurement m{fn, fn_name, {}};
    for (const char* r : rows) m.rows.emplace_back(r);
    registry().push_back(std::move(m));
}

// ------------------------------------------------------------------- session

int Session::cpu(int i) const {
    need_cpus(i + 1);
    return opt_.cpus[std::size_t(i)];
}

std::string Session::cpu_name(int i) const { return "cpu" + std::to_string(cpu(i)); }

void Session::need_cpus(int n) const {
    if (int(opt_.cpus.size()) < n)
        throw Skip("needs " + std::to_string(n) + " CPUs, this process may use " +
                   std::to_string(opt_.cpus.size()));
}

void Session::pin(int cpu) {
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(cpu, &set);
    if (sched_setaffinity(0, sizeof set, &set) != 0)
        fail_errno("sched_setaffinity(cpu" + std::to_string(cpu) + ")");
}

Stats Session::time_ops(const std::string& row, const std::string& config,
                        const std::function<void(std::uint64_t)>& body, double ops_per_iter) {
    return time_custom(
        row, config,
        [&](std::uint64_t n) {
            const std::uint64_t t0 = mono_ns();
            body(n);
            return double(mono_ns() - t0);
        },
        ops_per_iter);
}

Stats Session::time_custom(const std::string& row, const std::string& config,
                           const std::function<double(std::uint64_t)>& body, double ops_per_iter) {
    const Stats st = measure(body, ops_per_iter);
    std::string how = "median of " + std::to_string(st.runs) + " runs x " +
                      std::to_string(st.iters_per_run) + (ops_per_iter == 1 ? " ops" : " iterations");
    emit(row, config.empty() ? how : config + "; " + how, st.median, st.min, st.max);
    return st;
}

namespace {

// Median, min and max of per-operation times (sorted in place).
Stats stats_of(std::vector<double>& per_op, std::uint64_t n) {
    std::sort(per_op.begin(), per_op.end());
    Stats st;
    st.runs = int(per_op.size());
    st.iters_per_run = n;
    st.min = per_op.front();
    st.max = per_op.back();
    const std::size_t mid = per_op.size() / 2;
    st.median = per_op.size() % 2 ? per_op[mid] : (per_op[mid - 1] + per_op[mid]) / 2;
    return st;
}

}  // namespace

std::uint64_t Session::calibrate(const std::function<double(std::uint64_t)>& body) const {
    constexpr std::uint64_t kMaxIters = std::uint64_t(1) << 32;
    const double goal = opt_.run_ns;

    auto scaled = [&](std::uint64_t n, double t) {
        return std::clamp<std::uint64_t>(std::uint64_t(double(n) * goal / std::max(t, 1.0)), 1,
                                         kMaxIters);
    };
    // One cold call first: first touches, page faults, a partner thread or
    // process not yet running must not make the calibration think one
    // operation is slow.
    body(1);
    // Grow n until a run is long enough to time reliably, scale it to the
    // goal, and refine while a run still falls well short of it.
    std::uint64_t n = 1;
    for (;;) {
        const double t = body(n);
        if (abort_reason()) throw std::runtime_error(std::string(abort_reason()) + " while calibrating");
        if (t >= goal / 8 || n >= kMaxIters) {
            n = scaled(n, t);
            break;
        }
        n *= (t < goal / 100) ? 10 : 2;
    }
    for (int i = 0; i < 3; ++i) {
        const double t = body(n);
        if (t >= goal / 2 || n >= kMaxIters) break;
        n = scaled(n, t);
    }
    return n;
}

Stats Session::measure(const std::function<double(std::uint64_t)>& body, double ops_per_iter) {
    const std::uint64_t n = calibrate(body);
    for (int i = 0; i < opt_.warmup_runs; ++i) body(n);

    std::vector<double> per_op;
    per_op.reserve(std::size_t(opt_.runs));
    for (int i = 0; i < opt_.runs; ++i) {
        per_op.push_back(body(n) / (double(n) * ops_per_iter));
        if (abort_reason()) throw std::runtime_error(abort_reason());
    }
    return stats_of(per_op, n);
}

std::pair<Stats, Stats> Session::measure_interleaved(const std::function<double(std::uint64_t)>& a,
                                                     const std::function<double(std::uint64_t)>& b,
                                                     double ops_per_iter) {
    const std::uint64_t n = calibrate(a);
    b(1);  // b's cold call
    for (int i = 0; i < opt_.warmup_runs; ++i) {
        a(n);
        b(n);
    }
    std::vector<double> per_op_a, per_op_b;
    per_op_a.reserve(std::size_t(opt_.runs));
    per_op_b.reserve(std::size_t(opt_.runs));
    for (int i = 0; i < opt_.runs; ++i) {
        per_op_a.push_back(a(n) / (double(n) * ops_per_iter));
        per_op_b.push_back(b(n) / (double(n) * ops_per_iter));
        if (abort_reason()) throw std::runtime_error(abort_reason());
    }
    return {stats_of(per_op_a, n), stats_of(per_op_b, n)};
}

void Session::emit(const std::string& row, const std::string& config, double value, double min,
                   double max) {
    if (!find_row(row)) throw std::logic_error("row '" + row + "' is not in the catalog");
    out_->push_back(Measured{row, config, value, min, max, {}});
}

void Session::skip(const std::string& row, const std::string& reason) {
    if (!find_row(row)) throw std::logic_error("row '" + row + "' is not in the catalog");
    Measured m;
    m.name = row;
    m.skipped = reason;
    out_->push_back(std::move(m));
}

void Session::write_samples(const std::string& row, const std::vector<double>& ns) const {
    if (opt_.samples_dir.empty()) return;
    const std::string path = opt_.samples_dir + "/" + row + ".txt";
    std::FILE* f = std::fopen(path.c_str(), "w");
    if (!f) fail_errno("open " + path);
    for (double v : ns) std::fprintf(f, "%.0f\n", v);
    std::fclose(f);
}

void Session::write_data(const std::string& name, const std::string& json) const {
    if (opt_.samples_dir.empty()) return;
    const std::string path = opt_.samples_dir + "/" + name + ".json";
    std::FILE* f = std::fopen(path.c_str(), "w");
    if (!f) fail_errno("open " + path);
    std::fputs(json.c_str(), f);
    std::fclose(f);
}

}  // namespace chm::bench
