// The template port: a documented, empty port/<arch>/preempt.cpp. It owns
// the C++ half of preemption (port.hpp, "preemption"): reading a signal's
// ucontext and rewriting it so the interrupted task calls the kernel itself.
// Optional: a port without it sets CHM_PORT_HAS_PREEMPTION to 0 and its tasks
// switch only at kernel calls. src/meson.build compiles this file when
// preempt.S exists beside it.
#include "port.hpp"

#include <ucontext.h>

extern "C" void chm_port_preempt_trampoline();

namespace chm::port {

// The interrupted program counter / stack pointer of the signal whose
// handler received `ucontext` (its third argument): uc_mcontext's PC and SP
// fields, whatever the target calls them.
// Pre:  signal context; `ucontext` is the handler's own.
// Post: nothing is modified. Async-signal-safe (no locks, no libc).
std::uintptr_t interrupted_pc_from_signal(const void* ucontext) {
    (void)ucontext;
    return 0;
}

std::uintptr_t interrupted_sp_from_signal(const void* ucontext) {
    (void)ucontext;
    return 0;
}

// Make the interrupted task, once the handler returns, run
// chm_port_preempt_trampoline on its own stack as if it had been called at
// the interrupted instruction.
//
// What it must do: step below the ABI's red zone, leave on the task's stack
// whatever the trampoline needs to get back (at least the interrupted PC;
// on x86-64 pushed as a return address, on m68k with the CCR for `rtr`; on
// a machine where user code cannot restore every register and jump, like
// aarch64, a copy of the whole signal frame for rt_sigreturn), then set the
// ucontext's SP to the new stack top and its PC to the trampoline.
// Pre:  signal context on the kernel thread, interrupt mask held
//       (nest == 1); the interrupted PC is preemptible
//       (preemptible_pc_from_signal); the interrupted stack has
//       kPreemptFrameMax free bytes below its SP and red zone.
// Post: only the ucontext and the task-stack bytes below the interrupted SP
//       (at most kPreemptFrameMax of them) are modified; nothing runs yet.
//       Async-signal-safe.
void redirect_to_preempt_from_signal(void* ucontext) { (void)ucontext; }

}  // namespace chm::port
