// Assembly helpers every port supplies in tests/port/<arch>/regs.S.
#pragma once

#include <cstdint>

extern "C" {
// Load seed+1, seed+2, ... into every callee-saved integer register, a
// matching pattern into every callee-saved FP register, a non-default FP
// control state (round toward zero), call chm_port_switch(save, load), and
// on return compare everything. Returns 0 when all survived, otherwise the
// 1-based number of the first register that changed.
int chm_test_switch_check(void** save_sp, void* load_sp, std::uint64_t seed);

struct ChmTestClobberArgs {
    void** save;  // where this context's sp is saved
    void** back;  // where the checker's sp was saved
};
// Context entry: forever set every callee-saved register and the FP control
// state to garbage, then switch back to *back.
void chm_test_clobber_entry(void* args);

struct ChmTestSpProbe {
    std::uintptr_t sp_at_entry;
    void** save;
    void** back;
};
// Context entry: record the stack pointer as found on entry, switch back.
void chm_test_sp_probe_entry(void* probe);
}

extern "C" {
// Preemption conformance: number of registers the spin checks, the patterns
// it loads, and the spin itself. Loads every general and FP/SIMD register
// the port saves with chm_test_preempt_patterns[i], sets the carry (or the
// target's equivalent condition flag), spins `iterations` times touching no
// register, then stores every register into out[0..kChmPreemptRegs) and the
// flags word into out[kChmPreemptRegs].
extern const std::uint64_t chm_test_preempt_patterns[];
void chm_test_preempt_spin(std::uint64_t iterations, std::uint64_t* out);
}

// The layout of `out` per target (each regs.S documents its slots): how
// many 64-bit slots hold registers, and which bits of the flags word the
// spin set (mask) to which value (expected). The carry is always among them.
#if defined(__x86_64__)
inline constexpr int kChmPreemptRegs = 31;  // 15 integer, xmm0-15 low halves
inline constexpr std::uint64_t kChmPreemptFlagsMask = 0x1;       // rflags.CF
inline constexpr std::uint64_t kChmPreemptFlagsExpected = 0x1;
#elif defined(__aarch64__)
inline constexpr int kChmPreemptRegs = 97;  // x0-x30, v0-v31 (2 each), FPCR, FPSR
inline constexpr std::uint64_t kChmPreemptFlagsMask = 0xf0000000;  // NZCV
inline constexpr std::uint64_t kChmPreemptFlagsExpected = 0xb0000000;  // N C V
#elif defined(__m68k__)
inline constexpr int kChmPreemptRegs = 33;  // d0-d7 a0-a6, fp0-fp7 (2 each), FPCR FPSR
inline constexpr std::uint64_t kChmPreemptFlagsMask = 0x1f;      // CCR X N Z V C
inline constexpr std::uint64_t kChmPreemptFlagsExpected = 0x1b;  // X N V C
#endif
