// aarch64 context initialisation: lay out the frame chm_port_switch pops so
// that the first switch "returns" into chm_port_context_start, which calls
// entry(arg) with sp 16-byte aligned and the FPCR at its ABI default.
#include "port.hpp"

#include <cstring>

extern "C" void chm_port_context_start();

namespace chm::port {

namespace {

// Mirror of the frame in switch.S (offsets are load-bearing).
struct SwitchFrame {
    std::uint64_t x19_28[10];  // x19 = entry, x20 = arg
    std::uint64_t x29, x30;    // frame pointer, return address
    std::uint64_t d8_15[8];
    std::uint64_t fpcr;
    std::uint64_t pad;
};
static_assert(sizeof(SwitchFrame) == 176 && sizeof(SwitchFrame) % 16 == 0);

}  // namespace

void context_init(Context* ctx, void* stack_lo, std::size_t size,
                  void (*entry)(void*), void* arg) {
    auto top = reinterpret_cast<std::uintptr_t>(stack_lo) + size;
    top &= ~std::uintptr_t{15};
    // Popping the frame leaves sp == top: aligned when entry is called.
    auto* f = reinterpret_cast<SwitchFrame*>(top - sizeof(SwitchFrame));
    std::memset(f, 0, sizeof *f);
    f->x19_28[0] = reinterpret_cast<std::uint64_t>(entry);
    f->x19_28[1] = reinterpret_cast<std::uint64_t>(arg);
    f->x29 = 0;
    f->x30 = reinterpret_cast<std::uint64_t>(&chm_port_context_start);
    // FPCR 0: round to nearest, no flush-to-zero, no default NaN, all FP
    // exception traps disabled -- the Linux process default.
    f->fpcr = 0;
    ctx->sp = f;
}

}  // namespace chm::port
