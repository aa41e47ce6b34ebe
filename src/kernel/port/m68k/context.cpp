// m68k context initialisation: lay out the frame chm_port_switch pops so
// that the first switch returns into chm_port_context_start, which calls
// entry(arg) on a 4-byte aligned stack with the FPCR at its default.
#include "port.hpp"

#include <cstring>

extern "C" void chm_port_context_start();

namespace chm::port {

namespace {

// Mirror of the frame in switch.S (offsets are load-bearing; the target is
// big-endian and every field is a 32-bit word, so no padding sneaks in).
struct SwitchFrame {
    std::uint32_t fpcr;
    std::uint32_t fp2_7[6][3];  // 96-bit extended images
    std::uint32_t d2_7[6];      // d2 = arg
    std::uint32_t a2_6[5];      // a2 = entry, a6 = frame pointer
    std::uint32_t ret;          // popped by rts
};
static_assert(sizeof(SwitchFrame) == 124);

}  // namespace

void context_init(Context* ctx, void* stack_lo, std::size_t size,
                  void (*entry)(void*), void* arg) {
    auto top = reinterpret_cast<std::uintptr_t>(stack_lo) + size;
    top &= ~std::uintptr_t{kStackAlign - 1};
    // rts pops the return address and leaves sp == top.
    auto* f = reinterpret_cast<SwitchFrame*>(top - sizeof(SwitchFrame));
    // Zero fills fp2-fp7 with +0.0, a6 with the end of the frame chain.
    std::memset(f, 0, sizeof *f);
    f->d2_7[0] = reinterpret_cast<std::uintptr_t>(arg);
    f->a2_6[0] = reinterpret_cast<std::uintptr_t>(entry);
    f->ret = reinterpret_cast<std::uintptr_t>(&chm_port_context_start);
    // FPCR 0: round to nearest, extended precision, all exceptions masked
    // -- the Linux process default.
    f->fpcr = 0;
    ctx->sp = f;
}

}  // namespace chm::port
