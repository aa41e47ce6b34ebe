// The fast path of port::now_ns() (posix/clock.cpp has the design), inline
// in every caller: the kernel reads the clock at every switch, and the
// call, with the five registers it saved, cost ~2 ns of a 34 ns yield.
// Included by port.hpp only; nothing here is called directly.
#pragma once

#include <cstdint>

namespace chm::port::clock_detail {

// Per thread: the interval's start (cycles, ns), its rate (ns per cycle
// << 32), how many cycles it may run (`limit`: 0 until the thread's first
// rebase in counter mode, so every reading takes the slow path until
// then) and the last value returned (never less again). `gen` is odd while
// a rebase is under way and changes with each.
struct Interval {
    std::uint64_t cycles = 0, ns = 0, last = 0, mult = 0, limit = 0;
    std::uint32_t gen = 0;
};
extern constinit __attribute__((tls_model("initial-exec"))) thread_local Interval t_iv;

// Whether an interval (its start `cycles0`, `ns0` and rate `mult`) still
// held at a fresh pair (`cycles`, `ns`): its extrapolation within
// kIntervalDriftNs + 1000 ppm of the span of the clock (a counter behind
// `cycles0` predicts `ns0`). posix/clock.cpp turns the counter off when
// one did not.
inline constexpr std::uint64_t kIntervalDriftNs = 50000;
bool interval_agrees(std::uint64_t cycles0, std::uint64_t ns0, std::uint64_t mult, std::uint64_t cycles,
                     std::uint64_t ns);
// By how much the interval's extrapolation missed `ns` at `cycles`.
std::uint64_t interval_miss(std::uint64_t cycles0, std::uint64_t ns0, std::uint64_t mult, std::uint64_t cycles,
                            std::uint64_t ns);

// Everything else: no counter, a rebase due, a signal handler in the
// middle of a rebase or one that rebased during this reading.
std::uint64_t now_slow();

}  // namespace chm::port::clock_detail

namespace chm::port {

// Under AddressSanitizer + UBSan (make test-asan) the reading is out of
// line: GCC's null check there takes this inline access to another unit's
// thread_local for a null pointer (every test that reads the clock halted
// on it), while the %fs-relative address never is one.
#if CHM_PORT_HAS_CYCLE_COUNTER && !defined(__SANITIZE_ADDRESS__)
#define CHM_CLOCK_INLINE 1
#else
#define CHM_CLOCK_INLINE 0
#endif

inline std::uint64_t now_ns() {
#if CHM_CLOCK_INLINE
    clock_detail::Interval& iv = clock_detail::t_iv;
    const std::uint32_t gen = iv.gen;
    __atomic_signal_fence(__ATOMIC_SEQ_CST);
    const std::uint64_t base = iv.cycles, base_ns = iv.ns, mult = iv.mult, limit = iv.limit;
    const std::uint64_t d = cycle_counter() - base;
    __atomic_signal_fence(__ATOMIC_SEQ_CST);
    if ((gen & 1) || iv.gen != gen || d >= limit) [[unlikely]]
        return clock_detail::now_slow();
    std::uint64_t t = base_ns + std::uint64_t(((unsigned __int128)d * mult) >> 32);
    if (t < iv.last) t = iv.last;
    iv.last = t;
    return t;
#else
    return clock_detail::now_slow();
#endif
}

}  // namespace chm::port
