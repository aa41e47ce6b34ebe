// The template port: a documented, empty port/<arch>/fault.cpp. It owns the
// one architecture-specific step of the processor-exception contract
// (../fault.hpp): pointing a faulting context at a kernel entry.
#include "fault.hpp"

#include <ucontext.h>

namespace chm::port {

// Rewrite the signal's `ucontext` so that, when the handler returns, the
// interrupted thread calls fn() (which never returns) with a fresh frame.
//
// What it must do, with the register names of <sys/ucontext.h> for the
// target (uc_mcontext):
//  * take sp from the interrupted stack pointer when the caller passes 0,
//    below the ABI's red zone if it has one (x86-64: 128 bytes);
//  * align sp as the ABI wants at a call, then make the frame a call would
//    leave: a zero return address pushed (x86-64, m68k), or the link
//    register set to 0 (aarch64, most RISC ABIs);
//  * set the stack pointer and the program counter (fn) in the context;
//  * restore whatever the ABI requires at a call: flags (x86-64: DF clear)
//    and, where an unmasked FP trap could fire again in fn, the FP control
//    state (x86-64: MXCSR 0x1f80, x87 control word 0x37f).
// Called in signal context on the kernel thread, on the alternate signal
// stack: no locks, no allocation, nothing but stores into the context.
// Proven by tests/port (the fault cases) and the errors suite.
void redirect_to_call_from_signal(void* ucontext, void (*fn)(), std::uintptr_t sp) {
    (void)ucontext;
    (void)fn;
    (void)sp;
}

}  // namespace chm::port
