// x86-64 inline pieces of the port contract (see ../port.hpp).
#pragma once

#include <cpuid.h>

#include <cstdint>

// This port implements the preemption trampoline (preempt.S).
#define CHM_PORT_HAS_PREEMPTION 1
#define CHM_PORT_HAS_SWITCH_SAME_SITE 1  // switch.S: chm_port_switch_same_site
#define CHM_PORT_HAS_CALL_INDIRECT_RETURN 1  // switch.S: chm_port_call_indirect_return
#define CHM_PORT_HAS_STEER_BRANCH_HISTORY 1

namespace chm::port {

inline bool tas(volatile std::uint8_t* b) {
    // xchg with memory is locked and a full barrier.
    std::uint8_t old = 1;
    __asm__ __volatile__("xchgb %0, %1" : "+q"(old), "+m"(*b) : : "memory");
    return old == 0;
}

inline void tas_clear(volatile std::uint8_t* b) {
    __atomic_store_n(b, 0, __ATOMIC_RELEASE);
}

// Always inlined: the allocator spins with it, and none of its code may
// lie outside its own section (mem/mem_text.hpp), even at -O0.
__attribute__((always_inline)) inline void relax() { __builtin_ia32_pause(); }

// The time-stamp counter: constant rate on every x86-64 Linux keeps time
// with (the clock decides at run time whether to trust it). Not
// serialising: a reading may move a few instructions, which a clock
// accurate to tens of nanoseconds does not notice.
#define CHM_PORT_HAS_CYCLE_COUNTER 1
inline std::uint64_t cycle_counter() { return __builtin_ia32_rdtsc(); }
// The processor says its counter keeps one rate through every power
// state ("invariant TSC": CPUID 0x80000007, EDX bit 8). The clock asks it
// where Linux keeps time with a hypervisor's clock built on the counter.
inline bool cycle_counter_invariant() {
    unsigned a = 0, b = 0, c = 0, d = 0;
    return __get_cpuid(0x80000007, &a, &b, &c, &d) && (d & (1u << 8));
}

// Three conditional branches on the low bits of `key` (the incoming
// task's slot), just before the switch: they put the incoming task into
// the global branch history. Every switch returns to its task along the
// same kernel path, so without them the history at the final indirect
// jump to the task's caller (chm_port_call_indirect_return) is the same
// whoever comes in, and two tasks yielding to each other from different
// call sites mispredict it at every switch (a yield between two such
// tasks: 27.8 -> 19.6 ns; three or four tasks in turn: unchanged, ~21 and
// ~23 ns). The three branches are predicted as well as the order in
// which tasks run is: a repeating order costs nothing.
inline void steer_branch_history(std::uint32_t key) {
    __asm__ __volatile__(
        "test $1, %0\n\tjz 1f\n\tnop\n1:\n\t"
        "test $2, %0\n\tjz 2f\n\tnop\n2:\n\t"
        "test $4, %0\n\tjz 3f\n\tnop\n3:" : : "r"(key) : "cc");
}

inline constexpr const char* kArchName = "x86_64";
// The ABI's stack alignment at a call instruction.
inline constexpr unsigned kStackAlign = 16;
// At a function's first instruction, (sp + kSpAtEntryBias) % kStackAlign == 0
// (the call pushed an 8-byte return address onto an aligned stack).
inline constexpr unsigned kSpAtEntryBias = 8;
// Stack the preemption trampoline may use below an interrupted stack
// pointer: red zone, saved registers, alignment and an AVX-512 XSAVE area.
inline constexpr unsigned kPreemptFrameMax = 4096;

}  // namespace chm::port
