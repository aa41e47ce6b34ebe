// The benchmark harness: how a figure is measured, and how a file adds the
// measurement that produces one or more rows of the report.
//
// A row's metadata (unit, peer, the paper's figure, the target) lives in one
// place, the catalog (catalog.cpp); a measurement file only says how to get
// the number. Adding a kernel or backplane row is therefore:
//
//   // bench/kernel/task_create.cpp
//   #include "harness.hpp"
//   namespace {
//   void task_create(chm::bench::Session& s) {
//       ... set up ...
//       s.time_ops("task_create", "pinned " + s.cpu_name(0) + ", stack pool",
//                  [&](std::uint64_t n) { for (std::uint64_t i = 0; i < n; ++i) ...; });
//   }
//   }  // namespace
//   CHM_BENCH_MEASUREMENT(task_create, "task_create");
//
// plus the file's name in bench/meson.build. Until such a file exists the
// catalog row is reported as "not yet measured"; it never gets a number.
//
// Errors: the bench is not a real-time path, so it uses exceptions (Skip for
// "cannot be measured here", anything else for a failure) and RAII to clean
// up processes and named objects on every exit.
#pragma once

#include <cerrno>
#include <cmath>
#include <cstdint>
#include <functional>
#include <initializer_list>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace chm::bench {

inline constexpr double kNull = std::numeric_limits<double>::quiet_NaN();

// Many short runs rather than a few long ones: on a shared machine a run
// that another process preempted is an outlier the median drops, where a
// long run would average the disturbance into every sample.
struct Options {
    bool quick = false;
    int runs = 101;           // timed runs per row; the row reports their median
    int warmup_runs = 10;     // untimed runs after calibration
    double run_ns = 2e6;      // the length one timed run aims at
    double watchdog_s = 120;  // a measurement still running after this fails
    std::vector<int> cpus;    // CPUs this process may use (sched_getaffinity)
    std::string samples_dir;  // where distribution rows write raw samples
};

// The outcome of repeated runs: ns per operation.
struct Stats {
    double median = kNull, min = kNull, max = kNull;
    int runs = 0;
    std::uint64_t iters_per_run = 0;
};

// One measured row before the catalog's metadata is joined to it.
struct Measured {
    std::string name, config;
    double value = kNull, min = kNull, max = kNull;
    std::string skipped;  // non-empty: no figure, for this reason
    int round = 0;        // which round of the run produced it (0-based; main.cpp sets it)
};

// "This row cannot be measured on this machine" (a tool is missing, one CPU
// only, no permission): reported as skipped with the reason, not a failure.
struct Skip : std::runtime_error {
    using std::runtime_error::runtime_error;
};

// What a measurement function receives: options, CPUs, and the timing and
// reporting primitives. One Session per measurement.
class Session {
public:
    Session(const Options& opt, std::vector<Measured>* out) : opt_(opt), out_(out) {}

    bool quick() const { return opt_.quick; }
    const Options& options() const { return opt_; }

    // The i-th CPU this process may run on (i = 0, 1); cpu_name gives "cpu3".
    // need_cpus(2) throws Skip on a one-CPU machine.
    int cpu(int i) const;
    std::string cpu_name(int i) const;
    void need_cpus(int n) const;

    // Pin the calling thread to `cpu`. The harness restores the main thread's
    // affinity after every measurement, so a row only pins, never unpins.
    static void pin(int cpu);

    // The usual primitive: body(n) performs n iterations of `ops_per_iter`
    // operations each (2 for a ping-pong reported as RT/2). The harness
    // calibrates n so one run lasts about run_ns, warms up, repeats, and
    // emits the median ns per operation with the min and max over the runs.
    Stats time_ops(const std::string& row, const std::string& config,
                   const std::function<void(std::uint64_t n)>& body, double ops_per_iter = 1);

    // For rows whose runs need untimed setup: body(n) performs n iterations
    // and returns the nanoseconds it spent in the part it times.
    Stats time_custom(const std::string& row, const std::string& config,
                      const std::function<double(std::uint64_t n)>& body, double ops_per_iter = 1);

    // The method of time_custom without emitting a row: for figures that
    // feed another (a ratio, a scaling curve).
    Stats measure(const std::function<double(std::uint64_t n)>& body, double ops_per_iter = 1);

    // Two bodies measured by the method of measure, run by run in turn (a,
    // then b, the same n, calibrated on a): a figure and the floor it is
    // judged against, so both see the same conditions (a host that moves
    // its vCPUs during a run moves both). Emits nothing.
    std::pair<Stats, Stats> measure_interleaved(const std::function<double(std::uint64_t n)>& a,
                                                const std::function<double(std::uint64_t n)>& b,
                                                double ops_per_iter = 1);

    // A figure computed some other way (percentiles, a tool's own report).
    void emit(const std::string& row, const std::string& config, double value,
              double min = kNull, double max = kNull);

    // One row of a measurement that produces several cannot be measured here
    // (the others can): reported as skipped with the reason.
    void skip(const std::string& row, const std::string& reason);

    // Raw samples of a distribution row, for plots (written only when the
    // caller asked for them with --samples DIR).
    void write_samples(const std::string& row, const std::vector<double>& ns) const;

    // An experiment's data (JSON text) for run.py's plots and
    // bench/experiments.json; written only with --samples DIR, as DIR/name.json.
    void write_data(const std::string& name, const std::string& json) const;

private:
    // The iteration count that makes one run of `body` last about run_ns.
    std::uint64_t calibrate(const std::function<double(std::uint64_t n)>& body) const;

    const Options& opt_;
    std::vector<Measured>* out_;
};

// Monotonic nanoseconds (CLOCK_MONOTONIC, vDSO: no system call).
std::uint64_t mono_ns();

// Why the measuring thread must stop waiting, or nullptr: the per-measurement
// watchdog fired (the measurement overran) or a peer process died. Both
// arrive as signals without SA_RESTART, so a blocking call of the measuring
// thread returns EINTR; spin loops poll this instead.
const char* abort_reason();
bool watchdog_fired();
void clear_child_died();  // a new peer process is about to start

// Throw a descriptive error when a system call failed: "what: strerror".
// EINTR after abort_reason() became non-null reports that reason instead.
[[noreturn]] void fail_errno(const std::string& what, int err = errno);
inline void check(bool ok, const char* what) {
    if (!ok) [[unlikely]]
        fail_errno(what);
}
// After a blocking call failed: return (so the caller retries) on a stray
// EINTR, throw on anything else or once the watchdog fired. Usage:
//   while (sem_wait(s) != 0) eintr_or_fail("sem_wait");
inline void eintr_or_fail(const char* what) {
    if (errno == EINTR && !abort_reason()) return;
    fail_errno(what);
}

// ------------------------------------------------------------ registration

using MeasureFn = void (*)(Session&);

struct Measurement {
    MeasureFn fn;
    const char* fn_name;
    std::vector<std::string> rows;  // every row the function may emit
};

std::vector<Measurement>& registry();

struct Registrar {
    Registrar(MeasureFn fn, const char* fn_name, std::initializer_list<const char*> rows);
};

#define CHM_BENCH_CAT2(a, b) a##b
#define CHM_BENCH_CAT(a, b) CHM_BENCH_CAT2(a, b)
// Register `fn` as the measurement that produces the named catalog rows.
#define CHM_BENCH_MEASUREMENT(fn, ...)                                             \
    static const ::chm::bench::Registrar CHM_BENCH_CAT(chm_bench_registrar_,       \
                                                       __LINE__){fn, #fn, {__VA_ARGS__}}

}  // namespace chm::bench
