// aarch64 side of the processor-exception contract (../fault.hpp): point a
// faulting context at a kernel entry with a fresh call frame.
#include "fault.hpp"

#include <ucontext.h>

namespace chm::port {

void redirect_to_call_from_signal(void* ucontext, void (*fn)(), std::uintptr_t sp) {
    auto* uc = static_cast<ucontext_t*>(ucontext);
    if (!sp) sp = uc->uc_mcontext.sp;  // AAPCS64 has no red zone
    uc->uc_mcontext.sp = sp & ~std::uintptr_t{15};
    uc->uc_mcontext.pc = reinterpret_cast<std::uintptr_t>(fn);
    uc->uc_mcontext.regs[30] = 0;  // fn never returns
    uc->uc_mcontext.regs[29] = 0;  // end of the frame chain for unwinders
}

}  // namespace chm::port
