// The monotonic clock of every POSIX port.
//
// CLOCK_MONOTONIC through the vDSO costs ~24 ns on a kvm guest, more than a
// whole task switch; the kernel reads the clock at every switch (CPU
// accounting, quanta). Where the processor has a constant-rate cycle
// counter that Linux's clock is built on, now_ns() extrapolates from the
// last CLOCK_MONOTONIC reading of the calling thread with the counter
// (~10 ns), and reads CLOCK_MONOTONIC again at least every kRebaseNs: the
// error against CLOCK_MONOTONIC stays below the counter rate's error over
// that interval (NTP slews the clock by at most 500 ppm: 0.5 us per ms;
// the rate is measured over the whole process life, so in practice far
// less). Linux's clock is built on the counter when its clocksource is
// "tsc", and on a kvm guest whose clocksource is "kvm-clock" (the
// hypervisor's scaled counter: system time + (tsc - stamp) x rate) when
// the processor says the counter is invariant; such guests are often told
// "tsc=unstable" only because they may be moved to another host, so every
// rebase checks the interval it ends: a thread's extrapolation that missed
// the fresh reading by more than kIntervalDriftNs + 1000 ppm of the
// interval (a counter gone back counts as predicting the interval's start)
// turns the counter off for the process for good, with one line on stderr
// (readings still never go back; other threads' intervals run out within
// kRebaseNs). now_exact_ns() reads CLOCK_MONOTONIC and
// starts a new interval: the timer paths use it, so an expiry is never
// judged against a reading that trails the clock that fired it. Elsewhere
// (no counter, another clocksource, CHIMERA_CLOCK=vdso) both are
// CLOCK_MONOTONIC.
#include "port.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cstdlib>
#include <cstring>
#include <ctime>

namespace chm::port {

namespace {

std::uint64_t monotonic() {
    timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return std::uint64_t(ts.tv_sec) * 1000000000u + std::uint64_t(ts.tv_nsec);
}

#if CHM_PORT_HAS_CYCLE_COUNTER

constexpr std::uint64_t kRebaseNs = 1000000;
constexpr std::uint64_t kCalibrateNs = 200000;
// A (counter, clock) pair is read with the counter on both sides of the
// clock; further apart than this the thread was interrupted in between
// (the clock read alone is ~100 cycles), and the pair is read again.
constexpr std::uint64_t kPairSlackCycles = 2000;

enum : int { kUnknown = 0, kDeciding, kCounter, kVdso };
std::atomic<int> g_mode{kUnknown};
// The process's first (counter, clock) pair and the rate measured from it,
// written once before g_mode turns kCounter, read-only afterwards.
std::uint64_t g_anchor_cycles, g_anchor_ns, g_rebase_cycles;
unsigned __int128 g_first_mult;  // ns per cycle << 32, from the calibration
// Why the counter was turned off, if it was (clock_counter_dropped).
std::atomic<std::uint64_t> g_dropped_miss_ns{0}, g_dropped_span_ns{0};

// Per thread (clock_fast.hpp): the interval now_ns() extrapolates from.
using clock_detail::Interval;

// The counter at the middle of a clock reading, and that reading.
bool read_pair(std::uint64_t* cycles, std::uint64_t* ns) {
    for (int i = 0; i < 4; ++i) {
        const std::uint64_t c0 = cycle_counter(), n = monotonic(), c1 = cycle_counter();
        if (c1 >= c0 && c1 - c0 <= kPairSlackCycles) {
            *cycles = c0 + (c1 - c0) / 2;
            *ns = n;
            return true;
        }
    }
    return false;
}

bool clocksource_is(const char* buf, const char* name) {
    const std::size_t len = std::strlen(name);
    return std::strncmp(buf, name, len) == 0 && (buf[len] == '\n' || buf[len] == 0);
}

bool linux_keeps_time_with_the_counter() {
    if (const char* e = std::getenv("CHIMERA_CLOCK"); e && std::strcmp(e, "vdso") == 0) return false;
    const int fd = ::open("/sys/devices/system/clocksource/clocksource0/current_clocksource", O_RDONLY | O_CLOEXEC);
    if (fd < 0) return false;
    char buf[32] = {};
    const ssize_t n = ::read(fd, buf, sizeof buf - 1);
    ::close(fd);
    if (n <= 0) return false;
    return clocksource_is(buf, "tsc") || (clocksource_is(buf, "kvm-clock") && cycle_counter_invariant());
}

// Once per process, by the first caller; others read the clock meanwhile.
void decide() {
    int expect = kUnknown;
    if (!g_mode.compare_exchange_strong(expect, kDeciding)) return;
    if (!linux_keeps_time_with_the_counter()) {
        g_mode.store(kVdso, std::memory_order_release);
        return;
    }
    std::uint64_t n0 = 0, c0 = 0, n1 = 0, c1 = 0;
    bool ok = read_pair(&c0, &n0);
    while (ok && monotonic() - n0 < kCalibrateNs) {
    }
    ok = ok && read_pair(&c1, &n1);
    if (!ok || c1 <= c0 || n1 <= n0) {  // never a clean pair, or a counter that does not count
        g_mode.store(kVdso, std::memory_order_release);
        return;
    }
    g_anchor_cycles = c0;
    g_anchor_ns = n0;
    g_first_mult = ((unsigned __int128)(n1 - n0) << 32) / (c1 - c0);
    g_rebase_cycles = std::uint64_t(((unsigned __int128)kRebaseNs << 32) / g_first_mult);
    g_mode.store(kCounter, std::memory_order_release);
}

// One line on stderr when the counter is turned off, with write(2): the
// rebase may run in the timer's signal handler.
void say_dropped(std::uint64_t miss_ns, std::uint64_t span_ns) {
    char buf[160];
    std::size_t n = 0;
    const auto put = [&](const char* s) {
        while (*s && n < sizeof buf) buf[n++] = *s++;
    };
    const auto num = [&](std::uint64_t v) {
        char d[24];
        int k = 0;
        do d[k++] = char('0' + v % 10); while ((v /= 10) && k < 24);
        while (k && n < sizeof buf) buf[n++] = d[--k];
    };
    put("chimera: clock: the cycle counter missed CLOCK_MONOTONIC by ");
    num(miss_ns / 1000);
    put(" us over ");
    num(span_ns / 1000);
    put(" us; this process reads CLOCK_MONOTONIC from now on\n");
    (void)!::write(2, buf, n);
}

// A new interval for this thread from a fresh CLOCK_MONOTONIC reading; the
// rate from the whole span since the anchor (better with every rebase).
// No clean pair (the thread kept being interrupted): the clock itself,
// and the old interval stays until the next call.
std::uint64_t rebase(Interval& iv) {
    std::uint64_t c, n;
    if (!read_pair(&c, &n)) return monotonic();
    if (iv.limit && !clock_detail::interval_agrees(iv.cycles, iv.ns, iv.mult, c, n)) [[unlikely]] {
        // Moved to another host, or a counter the host does not keep in
        // step: the clock alone from now on, never below what was read.
        const std::uint64_t miss = clock_detail::interval_miss(iv.cycles, iv.ns, iv.mult, c, n), span = n - iv.ns;
        g_dropped_miss_ns.store(miss, std::memory_order_relaxed);
        g_dropped_span_ns.store(span, std::memory_order_relaxed);
        if (g_mode.exchange(kVdso, std::memory_order_acq_rel) == kCounter) say_dropped(miss, span);
        ++iv.gen;
        __atomic_signal_fence(__ATOMIC_SEQ_CST);
        iv.limit = 0;
        __atomic_signal_fence(__ATOMIC_SEQ_CST);
        ++iv.gen;
        return n > iv.last ? n : iv.last;
    }
    ++iv.gen;
    __atomic_signal_fence(__ATOMIC_SEQ_CST);
    const std::uint64_t span = c - g_anchor_cycles;
    iv.mult = span > 16 * g_rebase_cycles ? std::uint64_t(((unsigned __int128)(n - g_anchor_ns) << 32) / span)
                                          : std::uint64_t(g_first_mult);
    iv.cycles = c;
    iv.ns = n;
    iv.limit = g_rebase_cycles;
    if (n > iv.last) iv.last = n;
    const std::uint64_t t = iv.last;
    __atomic_signal_fence(__ATOMIC_SEQ_CST);
    ++iv.gen;
    return t;
}

#endif

}  // namespace

namespace clock_detail {

namespace {
// (d x m) >> 32, saturated at UINT64_MAX, in 64-bit arithmetic (a 32-bit
// port has no 128-bit integers; the check is unit-tested on every port).
std::uint64_t mul_shift32_sat(std::uint64_t d, std::uint64_t m) {
    constexpr std::uint64_t kLow = 0xffffffffu;
    const std::uint64_t dh = d >> 32, dl = d & kLow, mh = m >> 32, ml = m & kLow;
    std::uint64_t r = (dl * ml) >> 32, hi = 0;
    if (dh * mh > kLow) return UINT64_MAX;
    hi = (dh * mh) << 32;
    if (__builtin_add_overflow(r, hi, &r) || __builtin_add_overflow(r, dh * ml, &r) ||
        __builtin_add_overflow(r, dl * mh, &r))
        return UINT64_MAX;
    return r;
}
}  // namespace

std::uint64_t interval_miss(std::uint64_t cycles0, std::uint64_t ns0, std::uint64_t mult, std::uint64_t cycles,
                            std::uint64_t ns) {
    // A counter read a little behind the interval's start (another CPU's,
    // a few cycles apart) predicts the start itself.
    const std::uint64_t span = cycles > cycles0 ? mul_shift32_sat(cycles - cycles0, mult) : 0;
    std::uint64_t predicted;
    if (__builtin_add_overflow(ns0, span, &predicted)) predicted = UINT64_MAX;
    return predicted > ns ? predicted - ns : ns - predicted;
}

bool interval_agrees(std::uint64_t cycles0, std::uint64_t ns0, std::uint64_t mult, std::uint64_t cycles,
                     std::uint64_t ns) {
    if (ns < ns0) return false;
    return interval_miss(cycles0, ns0, mult, cycles, ns) <= kIntervalDriftNs + (ns - ns0) / 1000;
}

constinit __attribute__((tls_model("initial-exec"))) thread_local Interval t_iv;

// now_ns()'s fast path is inline (clock_fast.hpp); here the rest.
std::uint64_t now_slow() {
#if CHM_PORT_HAS_CYCLE_COUNTER
    if (g_mode.load(std::memory_order_acquire) == kCounter) [[likely]] {
        Interval& iv = t_iv;
        for (;;) {
            const std::uint32_t gen = iv.gen;
            if (gen & 1) [[unlikely]] return monotonic();  // a signal handler inside a rebase
            __atomic_signal_fence(__ATOMIC_SEQ_CST);
            const std::uint64_t base = iv.cycles, base_ns = iv.ns, mult = iv.mult;
            const std::uint64_t d = cycle_counter() - base;
            __atomic_signal_fence(__ATOMIC_SEQ_CST);
            if (iv.gen != gen) [[unlikely]] continue;  // a signal handler rebased meanwhile
            if (d >= g_rebase_cycles || base == 0) [[unlikely]] return rebase(iv);
            std::uint64_t t = base_ns + std::uint64_t(((unsigned __int128)d * mult) >> 32);
            if (t < iv.last) t = iv.last;
            iv.last = t;
            return t;
        }
    }
    if (g_mode.load(std::memory_order_relaxed) == kUnknown) decide();
    // Never below a reading the counter gave before it was turned off.
    const std::uint64_t m = monotonic(), last = t_iv.last;
    return m < last ? last : m;
#else
    return monotonic();
#endif
}

}  // namespace clock_detail

std::uint64_t now_exact_ns() {
#if CHM_PORT_HAS_CYCLE_COUNTER
    if (g_mode.load(std::memory_order_acquire) == kCounter) {
        Interval& iv = clock_detail::t_iv;
        if (!(iv.gen & 1)) return rebase(iv);
    }
    const std::uint64_t m = monotonic(), last = clock_detail::t_iv.last;
    return m < last ? last : m;
#else
    return monotonic();
#endif
}

bool clock_counter_dropped(std::uint64_t* miss_ns, std::uint64_t* span_ns) {
#if CHM_PORT_HAS_CYCLE_COUNTER
    const std::uint64_t span = g_dropped_span_ns.load(std::memory_order_relaxed);
    if (!span && !g_dropped_miss_ns.load(std::memory_order_relaxed)) return false;
    if (miss_ns) *miss_ns = g_dropped_miss_ns.load(std::memory_order_relaxed);
    if (span_ns) *span_ns = span;
    return true;
#else
    (void)miss_ns;
    (void)span_ns;
    return false;
#endif
}

bool clock_extrapolates() {
#if CHM_PORT_HAS_CYCLE_COUNTER
    if (g_mode.load(std::memory_order_acquire) == kUnknown) (void)now_ns();
    return g_mode.load(std::memory_order_acquire) == kCounter;
#else
    return false;
#endif
}

}  // namespace chm::port
