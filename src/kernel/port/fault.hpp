// The port contract, processor exceptions (part of port.hpp's contract; kept
// in its own header). A port turns the processor's synchronous exceptions on
// the kernel thread -- SIGSEGV, SIGBUS, SIGFPE and SIGILL on POSIX -- into a
// call of the kernel's fault handler, in signal context on the kernel
// thread's alternate signal stack. The kernel then either fail-stops the
// process or has the port redirect the interrupted context into a kernel
// entry, exactly as the preemption trampoline redirects a preempted task:
// nothing runs on a task stack inside the handler, and no task is ever
// switched inside it.
#pragma once

#include <cstdint>

namespace chm::port {

// What the processor reported (POSIX: SIGSEGV, SIGBUS, SIGFPE, SIGILL; the
// signal numbers stay in posix/fault.cpp).
enum class FaultKind : std::uint8_t {
    Access,      // a bad memory access (SIGSEGV)
    Bus,         // a bus error (SIGBUS)
    Arithmetic,  // integer division by zero, an FP trap (SIGFPE)
    Illegal,     // an illegal instruction (SIGILL)
};

struct FaultInfo {
    FaultKind kind;
    // The port's words for the cause ("address not mapped", ...), "signal
    // sent by a process" when the processor did not raise it, nullptr when
    // the port has none.
    const char* detail;
    std::uintptr_t addr;  // si_addr: the faulting address (or instruction)
    std::uintptr_t pc;    // the interrupted program counter
    std::uintptr_t sp;    // the interrupted stack pointer
    // Not a processor fault: the timer found no room below sp for the
    // preemption trampoline's frame (fault_no_room_from_signal). kind is
    // Access, addr the lowest byte the frame would have used.
    bool no_room = false;
};

// Called in signal context on the kernel thread, on the alternate signal
// stack, with every other signal blocked. It must either not return
// (fail-stop: write a diagnostic, _exit) or call
// redirect_to_call_from_signal() on `ucontext` before returning.
using FaultHandler = void (*)(const FaultInfo& f, void* ucontext);

// Install the handler for the four signals (SA_SIGINFO | SA_ONSTACK) and
// make the calling thread the one whose faults it sees; give that thread an
// alternate signal stack if it has none (a virtual-clock kernel has no
// timer, whose stack it would otherwise share). Faults on other threads go
// to the action installed before (the default: the process dies with the
// signal). Returns 0 or -errno. Kernel thread, once per kernel init.
int fault_init(FaultHandler handler);
// Restore the actions found by fault_init.
void fault_fini();
// True on the thread that called fault_init. Any context.
bool on_fault_thread();

// Report to the fault handler, from the timer's handler (signal context on
// the kernel thread, mask released by the caller), that the interrupted
// task has no room on its stack for the preemption frame: FaultInfo with
// no_room set, addr = `addr`. The handler then redirects the context (or
// fail-stops) as for a fault. Returns false, doing nothing, when no handler
// is installed or the caller is not the fault thread.
bool fault_no_room_from_signal(void* ucontext, std::uintptr_t addr);

// Rewrite `ucontext` so that, after the handler returns, the interrupted
// thread calls `fn()` (which never returns) with the stack pointer at
// `sp` (aligned by the port as for a call), or, with sp == 0, on the
// interrupted stack below its red zone. Whatever the ABI requires at a
// call is restored: x86-64 clears DF and resets MXCSR and the x87 control
// word (an unmasked FP trap must not fire again in the entry); the aarch64
// and m68k ABIs require nothing there, and those ports leave the FP control
// registers as the faulting code had them (Chimera never unmasks FP traps
// on them). Per target, in <arch>/fault.cpp.
void redirect_to_call_from_signal(void* ucontext, void (*fn)(), std::uintptr_t sp);

}  // namespace chm::port
