// m68k (68020/68030 + 68881/68882, Linux user mode) inline pieces of the
// port contract (see ../port.hpp): the test-and-set lock on the processor's
// own `tas` instruction, the spin-wait hint and the ABI constants.
#pragma once

#include <cstdint>

// This port implements the preemption trampoline (preempt.S).
#define CHM_PORT_HAS_PREEMPTION 1

namespace chm::port {

// `tas` is the 68k's indivisible read-modify-write: it tests the byte and
// sets its bit 7 in one locked bus cycle, which is what VMEbus boards use for
// backplane locks, so the same code works on a real board. Z reports whether
// the byte was zero before, i.e. whether we now own it.
//
// Under qemu-user, guest threads run on parallel host threads. qemu emulates
// `tas` on memory with an atomic fetch-or since 7.2 (target/m68k/translate.c;
// earlier versions did a plain load and store, marked "should be atomic").
// The conformance test MutualExclusionBetweenThreadsLosesNoIncrement runs on
// Debian's qemu 7.2 without losing an increment, while the same loop without
// the lock loses them, so the threads really do interleave. On an older qemu
// use `cas.b` (68020+), which qemu has always emulated atomically.
inline bool tas(volatile std::uint8_t* b) {
    std::uint8_t was_clear;
    __asm__ __volatile__("tas %1\n\tseq %0"
                         : "=d"(was_clear), "+m"(*b)
                         :
                         : "cc", "memory");
    return was_clear != 0;
}

inline void tas_clear(volatile std::uint8_t* b) {
    // In-order core: a compiler barrier plus the byte store is a release.
    __atomic_store_n(b, std::uint8_t{0}, __ATOMIC_RELEASE);
}

// The 68k has no spin-wait hint; nop also synchronises the pipeline on the
// 68040/060.
// Always inlined: the allocator spins with it, and none of its code may
// lie outside its own section (mem/mem_text.hpp), even at -O0.
__attribute__((always_inline)) inline void relax() { __asm__ __volatile__("nop" ::: "memory"); }

inline constexpr const char* kArchName = "m68k";
// The m68k SVR4/Linux ABI keeps the stack 4-byte aligned at calls (GCC
// itself assumes only 2, the architectural minimum for a word push, but the
// kernel, glibc and every call site keep 4; a 32-bit load from a 2-aligned
// sp costs an extra bus cycle on the 68020/030). `jsr` pushes a 4-byte
// return address, so at a function's first instruction sp + 4 is aligned
// too. The bias is 4 (the return address); modulo 4 it is the same as 0,
// but it says what the test checks.
inline constexpr unsigned kStackAlign = 4;
inline constexpr unsigned kSpAtEntryBias = 4;

// Stack the preemption trampoline uses below an interrupted stack pointer
// (the ABI has no red zone): the CCR and PC for `rtr`, d0-d7/a0-a6, the
// 96-bit images of fp0-fp7, FPCR/FPSR/FPIAR and 2 bytes of realignment
// (preempt.S).
inline constexpr unsigned kPreemptFrameMax = 192;

// 64-bit atomics are not lock-free on this target (libatomic takes a lock):
// port and kernel code must not use them, least of all in a signal handler.

}  // namespace chm::port
