// x86-64 side of the processor-exception contract (../fault.hpp): point a
// faulting context at a kernel entry with a fresh call frame.
#include "fault.hpp"

#include <ucontext.h>

namespace chm::port {

void redirect_to_call_from_signal(void* ucontext, void (*fn)(), std::uintptr_t sp) {
    auto* uc = static_cast<ucontext_t*>(ucontext);
    greg_t* g = uc->uc_mcontext.gregs;
    if (!sp) sp = std::uintptr_t(g[REG_RSP]) - 128;  // below the red zone
    sp &= ~std::uintptr_t{15};
    sp -= 8;  // as after a call: fn never returns, its return address is 0
    *reinterpret_cast<std::uint64_t*>(sp) = 0;
    g[REG_RSP] = greg_t(sp);
    g[REG_RIP] = greg_t(reinterpret_cast<std::uintptr_t>(fn));
    g[REG_EFL] &= ~greg_t{0x400};  // DF clear, as the ABI wants at a call
    if (fpregset_t fp = uc->uc_mcontext.fpregs) {
        // An unmasked FP trap must not fire again in the entry.
        fp->mxcsr = 0x1f80;
        fp->cwd = 0x37f;
        fp->swd = 0;
        fp->ftw = 0;
    }
}

}  // namespace chm::port
