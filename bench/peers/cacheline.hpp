// The cache-line ping-pong, the floor under a polling hand-off: one side
// stores an odd value, the other answers with the next even one. Used by
// peer_cacheline_pingpong_xcore (two threads) and by
// peer_cacheline_pingpong_rtpus (rsem_handoff_polling's two tasks), so
// both floors run the same loops.
#pragma once

#include <atomic>
#include <cstdint>
#include <stdexcept>

#include "../harness.hpp"

namespace chm::bench {

inline void cpu_relax() {
#if defined(__x86_64__)
    __builtin_ia32_pause();
#elif defined(__aarch64__)
    __asm__ __volatile__("yield");
#endif
}

// The line that moves, alone in its cache line.
struct alignas(64) PingLine {
    std::atomic<std::uint64_t> seq{0};
};
// The floor between two tasks of two RTPUs (rsem_handoff_polling,
// msgq_oneway_polling_xrtpu), placed in common memory: the line that
// moves, and on a line of its own whether the partner, when the next
// hand-off wakes it, answers the line until kPingStop.
struct TaskLineFloor {
    PingLine line;
    alignas(64) std::atomic<std::uint32_t> pass_line{0};
};
// The floor in a segment allocated with 64 bytes to spare.
inline TaskLineFloor* task_line_floor_in(void* segment) {
    const auto p = reinterpret_cast<std::uintptr_t>(segment);
    return reinterpret_cast<TaskLineFloor*>((p + 63) & ~std::uintptr_t(63));
}

// An even value no run reaches: the answering side returns.
inline constexpr std::uint64_t kPingStop = UINT64_MAX - 1;

// The answering side: every odd value gets the next even one, until
// kPingStop.
inline void answer_pings(PingLine& l) {
    for (;;) {
        const std::uint64_t v = l.seq.load(std::memory_order_acquire);
        if (v == kPingStop) return;
        if (v & 1) l.seq.store(v + 1, std::memory_order_release);
        else cpu_relax();
    }
}

// `n` round trips from the line's present (even) value; the ns they took.
inline double send_pings(PingLine& l, std::uint64_t n) {
    std::uint64_t v = l.seq.load(std::memory_order_relaxed);
    const std::uint64_t t0 = mono_ns();
    for (const std::uint64_t end = v + 2 * n; v < end; v += 2) {
        l.seq.store(v + 1, std::memory_order_release);
        for (std::uint32_t spins = 0; l.seq.load(std::memory_order_acquire) != v + 2;) {
            cpu_relax();
            if (++spins == 0 && abort_reason()) throw std::runtime_error(abort_reason());
        }
    }
    return double(mono_ns() - t0);
}

}  // namespace chm::bench
