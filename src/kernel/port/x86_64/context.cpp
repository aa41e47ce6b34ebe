// x86-64 context initialisation: lay out the frame chm_port_switch pops.
#include "port.hpp"

#include <cstring>

extern "C" void chm_port_context_start();

namespace chm::port {

void context_init(Context* ctx, void* stack_lo, std::size_t size,
                  void (*entry)(void*), void* arg) {
    auto top = reinterpret_cast<std::uintptr_t>(stack_lo) + size;
    top &= ~std::uintptr_t{15};
    auto* sp = reinterpret_cast<std::uint64_t*>(top);
    // `ret` into context_start leaves rsp == top, 16-aligned.
    *--sp = reinterpret_cast<std::uint64_t>(&chm_port_context_start);
    *--sp = 0;                                        // rbp
    *--sp = 0;                                        // rbx
    *--sp = reinterpret_cast<std::uint64_t>(entry);   // r12
    *--sp = reinterpret_cast<std::uint64_t>(arg);     // r13
    *--sp = 0;                                        // r14
    *--sp = 0;                                        // r15
    // ABI default FP control: MXCSR 0x1f80 (all masked, nearest), x87 0x037f.
    const std::uint32_t mxcsr = 0x1f80;
    const std::uint16_t fpucw = 0x037f;
    *--sp = 0;
    std::memcpy(sp, &mxcsr, 4);
    std::memcpy(reinterpret_cast<char*>(sp) + 4, &fpucw, 2);
    ctx->sp = sp;
}

}  // namespace chm::port
