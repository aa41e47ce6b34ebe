// What the kernel rows share: a kernel per measurement (RAII), running a
// body inside a task with its exceptions carried out of the kernel, a cheap
// inline cycle clock for intervals that start in one task and end in
// another, and a gap recorder for "time stolen from a running task".
#pragma once

#include <cstdint>
#include <exception>
#include <functional>
#include <string>
#include <vector>

#include "../harness.hpp"
#include "chimera/chimera.h"

namespace chm::bench::kb {

// ---- a kernel for one measurement

// Defaults: what chm_kernel_config_init gives a user (MUF, a 1 ms quantum,
// CPU time charged at every switch), which a target row is judged on
// (PERF.md, "the default configuration"); kDefaultConfig says so in a row.
struct KernelOpts {
    chm_sched_policy policy = CHM_SCHED_MUF;
    int cpu_accounting = 1;
    std::uint64_t quantum_ns = 1000000;
    int virtual_clock = 0;
    std::size_t default_stack = 64 * 1024;
};

inline constexpr const char* kDefaultConfig =
    "default config (MUF, 1 ms quantum, CPU time charged at every switch)";

// chm_kernel_init in the constructor (throws on failure), chm_kernel_fini
// in the destructor, so a failing measurement leaves no kernel behind.
class Kernel {
public:
    explicit Kernel(const KernelOpts& o = {});
    ~Kernel();
    Kernel(const Kernel&) = delete;
    Kernel& operator=(const Kernel&) = delete;
    // chm_kernel_run, then rethrow what a task caught (see guarded()).
    void run() { run_and_rethrow(); }
    // The same for a kernel initialised elsewhere (the backplane rows'
    // RTPUs, bench/ipc/rtpu.cpp), which start with forget_failure().
    static void run_and_rethrow();
    static void forget_failure();
    // Record a failure (the first one wins): the exception in flight (from
    // a catch block in a task), or one made by the caller; then, outside
    // the catch block, stop the kernel.
    static void store_current_exception();
    static void store_failure(std::exception_ptr e);
    static void stop_failed();
};

// Wrap a task body: an exception must not unwind through a context switch,
// so it is caught in the task, stored, the kernel is stopped and
// Kernel::run rethrows it.
template <class F>
void guarded(F&& f) {
    bool failed = false;
    try {
        f();
    } catch (...) {
        Kernel::store_current_exception();
        failed = true;
    }
    // Stopping switches away for good: never from inside a catch block,
    // whose bookkeeping belongs to the OS thread all tasks share.
    if (failed) Kernel::stop_failed();
}

// Spawn with the fields the rows use; throws on failure.
struct TaskSpec {
    int priority = 1;
    std::uint64_t period_ns = 0, start_ns = 0, wcet_ns = 0, deadline_ns = 0;
    int critical = 0;
    std::size_t stack = 0;
    chm_deadline_handler_t on_deadline = nullptr;
    void* on_deadline_arg = nullptr;
    const char* name = nullptr;
};
chm_tid_t spawn(void (*fn)(void*), void* arg, const TaskSpec& t);
chm_tid_t spawn(void (*fn)(void*), void* arg, int priority);

// A std::function as a task body (guarded).
chm_tid_t spawn_fn(std::function<void()>* fn, const TaskSpec& t);

// ---- the cycle clock

// A cycle counter read inline, in the bench's own code. Two reasons: it is
// cheaper than the vDSO clock (~25 ns on a kvm-clock guest), and code that
// waits to be preempted must not sit in the vDSO, where the kernel defers
// preemption (it only preempts code of the main program).
inline std::uint64_t ticks() {
#if defined(__x86_64__)
    return __builtin_ia32_rdtsc();
#elif defined(__aarch64__)
    std::uint64_t v;
    asm volatile("mrs %0, cntvct_el0" : "=r"(v));
    return v;
#else
    return mono_ns();
#endif
}

struct TickClock {
    double ns_per_tick = 1;
    double pair_ns = 0;  // two back-to-back ticks() reads: subtracted from intervals
    std::string name;    // "TSC", "CNTVCT" or "CLOCK_MONOTONIC"
    double ns(std::uint64_t dt) const { return double(dt) * ns_per_tick; }
    std::uint64_t from_ns(double ns) const { return std::uint64_t(ns / ns_per_tick); }
};
// Calibrated once (25 ms against CLOCK_MONOTONIC).
const TickClock& tick_clock();

// ---- stolen time

// Spin until ticks() reaches `end`, recording every gap between two
// consecutive reads longer than `thresh` ticks: the times something else
// (a signal handler, the kernel, the host) took the CPU. Returns the
// number of loop iterations; gaps beyond `cap` are dropped.
struct Gap {
    std::uint64_t at, len;  // ticks: the read before the gap, the gap's length
};
std::uint64_t spin_gaps(std::uint64_t end, std::uint64_t thresh, std::vector<Gap>* out,
                        std::size_t cap);

// One spin window: the clocks read at its start, its length and its gaps.
struct SpinWindow {
    std::uint64_t mono0 = 0, tick0 = 0, iters = 0, spin_ticks = 0;
    std::vector<Gap> gaps;
};
// Match each event (CLOCK_MONOTONIC ns, ascending) to the first gap of `w`
// that ends after it and starts at most 300 us after it; append the gap's
// length minus one plain loop iteration (ns) to `stolen`. Events before the
// window began are ignored. Returns the number of gaps left unmatched.
int match_gaps(const SpinWindow& w, const std::vector<std::uint64_t>& events,
               std::vector<double>* stolen, int* expected);

// ---- figures

// Median, min and max of per-run figures.
Stats stats_of(std::vector<double> v);
double percentile(std::vector<double>& sorted, double q);  // sorted ascending

std::string fmt_ns(double ns);  // "123 ns", "4.56 us"
std::string pinned(Session& s);  // "pinned cpu0, one RTPU"
std::string clock_used();        // which clock the switch reads (port::clock_extrapolates)

}  // namespace chm::bench::kb
