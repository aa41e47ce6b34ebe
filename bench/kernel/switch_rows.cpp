// Task-to-task switches through the scheduler: yield to an equal task (the
// performance target) and the Table 1 context switch with live FPU state. Two
// equal-priority tasks yield to each other; one yield of the timing task is
// two switches (to the partner and back), so the figure is the round / 2.
#include <cfenv>

#include "kbench.hpp"

namespace chm::bench {
namespace {

struct Yield {
    volatile bool stop = false;
};
void partner(void* p) {
    auto* a = static_cast<Yield*>(p);
    while (!a->stop) chm_task_yield();
}

Stats yield_cost(Session& s, const kb::KernelOpts& o) {
    kb::Kernel k(o);
    Yield a;
    Stats st;
    std::function<void()> body = [&] {
        st = s.measure([&](std::uint64_t n) {
            const std::uint64_t t0 = mono_ns();
            for (std::uint64_t i = 0; i < n; ++i) chm_task_yield();
            return double(mono_ns() - t0);
        }, 2);
        a.stop = true;
    };
    kb::spawn_fn(&body, {});
    kb::spawn(partner, &a, 1);
    k.run();
    return st;
}

void yield_row(Session& s) {
    Session::pin(s.cpu(0));
    const Stats dflt = yield_cost(s, {});
    const Stats fixed = yield_cost(s, {CHM_SCHED_FIXED, 1, 0});
    const Stats st = yield_cost(s, {CHM_SCHED_FIXED, 0, 0});
    // The default configuration is the figure; the faster settings beside it.
    s.emit("yield_switch",
           kb::pinned(s) + ", " + kb::kDefaultConfig + ", " + kb::clock_used() + "; two equal tasks calling chm_task_yield in turn; one "
                           "switch (a round / 2) including the quantum's re-arm; FIXED policy, no quantum: " +
               kb::fmt_ns(fixed.median) + "; FIXED, no quantum, cpu_accounting 0 (charged at ticks only): " +
               kb::fmt_ns(st.median) + "; median of " + std::to_string(dflt.runs) + " runs x " +
               std::to_string(dflt.iters_per_run) + " rounds",
           dflt.median, dflt.min, dflt.max);
    s.emit("yield_switch_vs_clocked_fiber",
           "yield_switch's figure (default config) beside a fiber switch that charges CPU time, as "
           "cpu_accounting 1 (the default) must at the least",
           dflt.median, dflt.min, dflt.max);
}
CHM_BENCH_MEASUREMENT(yield_row, "yield_switch", "yield_switch_vs_clocked_fiber");

// ---- live FP state: each task keeps four doubles in a dependency chain
// that is live across every switch. The ABI makes every FP data register
// caller-saved, so the compiler spills and reloads them around the call;
// the switch itself carries the FP control state (x86-64: MXCSR, x87 CW).
struct Fp {
    volatile bool stop = false;
    volatile double sink = 0;
    bool towardzero = false;  // the partner runs another rounding mode
};

__attribute__((noinline)) void not_a_switch() { asm volatile("" ::: "memory"); }

template <void (*Call)()>
double fp_loop(std::uint64_t n, double seed) {
    double a = seed, b = seed + 1, c = seed + 2, d = seed + 3;
    for (std::uint64_t i = 0; i < n; ++i) {
        a = a * 0.999999 + b * 1e-7;
        b = b * 0.999998 + c * 1e-7;
        c = c * 0.999997 + d * 1e-7;
        d = d * 0.999996 + a * 1e-7;
        Call();
    }
    return a + b + c + d;
}

void fp_partner(void* p) {
    auto* a = static_cast<Fp*>(p);
    if (a->towardzero) std::fesetround(FE_TOWARDZERO);
    double x = 0;
    while (!a->stop) x += fp_loop<chm_task_yield>(64, x * 1e-9 + 1);
    a->sink = x;
}

Stats fp_cost(Session& s, bool towardzero, Stats* alone) {
    kb::Kernel k({CHM_SCHED_FIXED, 1, 0});
    Fp a;
    a.towardzero = towardzero;
    Stats st;
    std::function<void()> body = [&] {
        if (alone)
            *alone = s.measure([&](std::uint64_t n) {
                const std::uint64_t t0 = mono_ns();
                a.sink = fp_loop<not_a_switch>(n, 1.0);
                return double(mono_ns() - t0);
            });
        st = s.measure([&](std::uint64_t n) {
            const std::uint64_t t0 = mono_ns();
            a.sink = fp_loop<chm_task_yield>(n, 1.0);
            return double(mono_ns() - t0);
        }, 2);
        a.stop = true;
    };
    kb::spawn_fn(&body, {});
    kb::spawn(fp_partner, &a, 1);
    k.run();
    return st;
}

void fpu_row(Session& s) {
    Session::pin(s.cpu(0));
    Stats alone;
    const Stats st = fp_cost(s, false, &alone);
    const Stats mixed = fp_cost(s, true, nullptr);
    s.emit("context_switch_fpu",
           kb::pinned(s) + ", FIXED policy, cpu_accounting 1 (default); two equal tasks each keep "
                           "four doubles live in a dependency chain across every chm_task_yield "
                           "(spilled/reloaded by the compiler: FP data registers are caller-saved "
                           "in the ABI; the switch carries the FP control state); one switch incl. "
                           "the FP work between switches (the same work + a plain call alone: " +
               kb::fmt_ns(alone.median) + "); with the partner in another rounding mode "
                                          "(FE_TOWARDZERO, control state reloaded each switch): " +
               kb::fmt_ns(mixed.median) + "; median of " + std::to_string(st.runs) + " runs x " +
               std::to_string(st.iters_per_run) + " rounds",
           st.median, st.min, st.max);
}
CHM_BENCH_MEASUREMENT(fpu_row, "context_switch_fpu");

}  // namespace
}  // namespace chm::bench
