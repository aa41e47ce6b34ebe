// The template port: a documented, empty port/<arch>/arch.hpp. It owns the
// inline half of the port contract (../port.hpp): the test-and-set lock, the
// spin-wait hint and the constants that describe the target's ABI. Copy this
// folder to port/<arch>/, fill in every entry, and follow "Adding a target"
// below. Model: Zephyr's kernel_arch_interface.h and ChibiOS's
// os/common/ports/templates/chcore.h -- every entry says what it must do,
// what holds before (Pre) and what the kernel may rely on after (Post).
//
// Adding a target
// ---------------
// 1. Folders. src/kernel/port/<arch>/ with arch.hpp, switch.S, context.cpp
//    (and, for preemption, preempt.cpp and preempt.S); tests/port/<arch>/
//    regs.S with the helpers declared in tests/port/regs_helpers.hpp.
//    <arch> is meson's cpu_family name (x86_64, aarch64, m68k, riscv64, ...).
// 2. meson. The top meson.build sets `arch = host_machine.cpu_family()` and
//    stops on any family not in its list: add <arch> there. Nothing else in
//    meson changes: src/meson.build compiles kernel/port/<arch>/context.cpp
//    and switch.S, adds preempt.cpp/preempt.S when preempt.S exists, and puts
//    kernel/port/<arch> on the include path, so `#include "arch.hpp"` in
//    port.hpp finds this file; tests/port/meson.build assembles
//    <arch>/regs.S into the conformance test.
// 3. Cross build. cross/<arch>.ini names the cross compilers and, because
//    binfmt_misc may not be mounted, an explicit exe_wrapper (qemu-<arch>
//    -L /usr/<triplet>, with a -cpu whose libc runs). Cross builds tag every
//    test with the suite <arch>; add `test-<arch>` to the Makefile like
//    test-m68k.
// 4. Conformance. `meson test -C build-<arch> --suite <arch>` must pass the
//    `port` test: ring of contexts, callee-saved registers across a switch,
//    stack alignment at entry, default FP control in a new context, TAS
//    mutual exclusion between threads, the timer, and (once
//    CHM_PORT_HAS_PREEMPTION is 1) registers across a preemption.
//
// An emulator is not the hardware: check that the emulator implements your
// atomic and FP control instructions faithfully (for the m68k port, qemu
// 7.2's `tas` proved atomic but its FP control register moves to memory did
// not) and say in a comment what you checked.
#pragma once

#error "port/template is documentation: copy it to port/<arch>/ and fill it in"

#include <cstdint>

// Define to 1 once preempt.cpp and preempt.S implement the preemption
// section of port.hpp. Until then the posix timer handler never redirects a
// task, the kernel switches only at kernel calls, and the conformance test
// test_port_preempt reports itself skipped.
#define CHM_PORT_HAS_PREEMPTION 0

// Optional, for speed only (port.hpp has a portable fallback for each):
//   CHM_PORT_HAS_SWITCH_SAME_SITE     chm_port_switch_same_site (switch.S)
//   CHM_PORT_HAS_CALL_INDIRECT_RETURN chm_port_call_indirect_return (switch.S)
//   CHM_PORT_HAS_STEER_BRANCH_HISTORY steer_branch_history(key) here
// Each is a branch-prediction aid measured on one processor (x86_64/); a
// port takes them only with figures from its own.

namespace chm::port {

// Atomically set the byte at `b` and report whether it was clear before
// (true: the caller now owns the lock).
// Pre:  `b` is any byte of ordinary or shared (mmap'd, multi-process)
//       memory; any context, including a signal handler.
// Post: the byte is non-zero. On true, no load or store of the caller that
//       follows in program order is performed before the set (acquire);
//       the operation is atomic against other threads and other processes
//       mapping the same memory, on every core of the machine. Use the
//       processor's own indivisible instruction (xchg, swp/ldaxr-stxr, tas,
//       cas), not a lock: a backplane lock must work between processes.
inline bool tas(volatile std::uint8_t* b) {
    (void)b;
    return false;
}

// Clear a byte set by tas().
// Pre:  the caller owns the byte (its tas() returned true); any context.
// Post: the byte is zero; every load and store of the caller before the
//       clear is visible to the next owner (release).
inline void tas_clear(volatile std::uint8_t* b) { (void)b; }

// Tell the processor the caller is spinning (x86 pause, Arm yield, a nop
// where there is no hint). No ordering, no side effect; any context.
// Always inlined: the allocator spins with it, and none of its code may
// lie outside its own section (mem/mem_text.hpp), even at -O0.
__attribute__((always_inline)) inline void relax() {}

// Name of the target, printed by tests and the kernel's banner.
inline constexpr const char* kArchName = "template";

// The ABI's stack alignment at a call instruction, in bytes (x86-64 and
// aarch64: 16; m68k Linux: 4). context_init aligns new stacks to it.
inline constexpr unsigned kStackAlign = 16;

// What a call pushes: at a function's first instruction,
// (sp + kSpAtEntryBias) % kStackAlign == 0. 0 when the return address goes
// to a register (aarch64, RISC-V), the size of the return address when the
// call pushes it (x86-64: 8; m68k: 4). The conformance test checks it.
inline constexpr unsigned kSpAtEntryBias = 0;

// Bytes the preemption trampoline may use below an interrupted stack
// pointer: the ABI's red zone, the interrupted register state the
// trampoline saves (or the signal frame it copies), and alignment. The
// kernel keeps this much free at the bottom of every task stack.
inline constexpr unsigned kPreemptFrameMax = 0;

}  // namespace chm::port
