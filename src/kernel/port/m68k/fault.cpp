// m68k side of the processor-exception contract (../fault.hpp): point a
// faulting context at a kernel entry with a fresh call frame. Checked under
// qemu-user, which restores the PC from the ucontext; a real 68030's bus
// error frame would need its fault/rerun state cleared as well.
#include "fault.hpp"

#include <ucontext.h>

namespace chm::port {

void redirect_to_call_from_signal(void* ucontext, void (*fn)(), std::uintptr_t sp) {
    greg_t* g = static_cast<ucontext_t*>(ucontext)->uc_mcontext.gregs;
    if (!sp) sp = std::uint32_t(g[R_SP]);  // no red zone
    sp &= ~std::uintptr_t{3};
    sp -= 4;  // as after jsr: fn never returns, its return address is 0
    *reinterpret_cast<std::uint32_t*>(sp) = 0;
    g[R_SP] = greg_t(sp);
    g[R_PC] = greg_t(reinterpret_cast<std::uintptr_t>(fn));
}

}  // namespace chm::port
