// aarch64 inline pieces of the port contract (see ../port.hpp): the
// test-and-set lock, the spin-wait hint and the ABI constants (AAPCS64).
#pragma once

#include <cstdint>

// This port implements the preemption trampoline (preempt.S).
#define CHM_PORT_HAS_PREEMPTION 1

namespace chm::port {

inline bool tas(volatile std::uint8_t* b) {
    // A byte exchange with acquire ordering: accesses after a successful
    // tas() cannot move before it. GCC emits SWPAB on LSE cores (through
    // libgcc's outline atomics on a generic build) and an LDAXRB/STXRB loop
    // otherwise; both are atomic against other threads and processes.
    return __atomic_exchange_n(b, std::uint8_t{1}, __ATOMIC_ACQUIRE) == 0;
}

inline void tas_clear(volatile std::uint8_t* b) {
    __atomic_store_n(b, std::uint8_t{0}, __ATOMIC_RELEASE);
}

// Always inlined: the allocator spins with it, and none of its code may
// lie outside its own section (mem/mem_text.hpp), even at -O0.
__attribute__((always_inline)) inline void relax() { __asm__ __volatile__("yield" ::: "memory"); }

inline constexpr const char* kArchName = "aarch64";
// AAPCS64: sp is 16-byte aligned at every public interface, and a call
// pushes nothing (the return address goes to x30), so at a function's first
// instruction (sp + kSpAtEntryBias) % kStackAlign == 0 with no bias.
inline constexpr unsigned kStackAlign = 16;
inline constexpr unsigned kSpAtEntryBias = 0;
// Stack the preemption trampoline may use below an interrupted stack
// pointer (AAPCS64 has no red zone): a copy of the kernel's signal frame
// (siginfo 128 + ucontext 4560 bytes, the FP/SIMD record inside it), which
// rt_sigreturn consumes to resume the task, rounded up with room for
// alignment. Cores whose SVE/SME state does not fit the ucontext's 4 KiB
// record area (vector length above 512 bits) need more: see preempt.cpp.
inline constexpr unsigned kPreemptFrameMax = 4864;

}  // namespace chm::port
