// m68k side of the preemption contract: read a signal's ucontext and
// redirect it so the interrupted task, after sigreturn, calls the kernel
// itself through chm_port_preempt_trampoline (preempt.S).
#include "port.hpp"

#include <ucontext.h>

extern "C" void chm_port_preempt_trampoline();

namespace chm::port {

std::uintptr_t interrupted_pc_from_signal(const void* ucontext) {
    return std::uint32_t(static_cast<const ucontext_t*>(ucontext)->uc_mcontext.gregs[R_PC]);
}

std::uintptr_t interrupted_sp_from_signal(const void* ucontext) {
    return std::uint32_t(static_cast<const ucontext_t*>(ucontext)->uc_mcontext.gregs[R_SP]);
}

void redirect_to_preempt_from_signal(void* ucontext) {
    greg_t* g = static_cast<ucontext_t*>(ucontext)->uc_mcontext.gregs;
    // Build what `rtr` pops at the end of the trampoline: the CCR word on
    // top, the interrupted PC under it. The m68k ABI has no red zone, and a
    // user-mode sigreturn restores only the CCR half of the SR, so the low
    // byte of the saved SR is all there is to carry.
    auto sp = std::uintptr_t(std::uint32_t(g[R_SP]));
    sp -= 4;
    *reinterpret_cast<std::uint32_t*>(sp) = std::uint32_t(g[R_PC]);
    sp -= 2;
    *reinterpret_cast<std::uint16_t*>(sp) = std::uint16_t(g[R_PS] & 0xff);
    g[R_SP] = greg_t(sp);
    g[R_PC] = greg_t(reinterpret_cast<std::uintptr_t>(&chm_port_preempt_trampoline));
}

}  // namespace chm::port
