// x86-64 side of the preemption contract: read and redirect a signal's
// ucontext, and size the XSAVE area the trampoline uses.
#include "port.hpp"

#include <cpuid.h>
#include <ucontext.h>

extern "C" {
void chm_port_preempt_trampoline();
// Read by preempt.S. Size 0 means "no XSAVE: use FXSAVE".
__attribute__((visibility("hidden"))) std::uint32_t chm_port_xsave_size = 0;
__attribute__((visibility("hidden"))) std::uint32_t chm_port_xsave_mask = 0;
}

namespace chm::port {

namespace {

// x87, SSE, AVX and the AVX-512 components. AMX tile data (bits 17-18) is
// left out on purpose: it is 8 KiB and Linux enables it per process only on
// request, which a control task never makes.
constexpr std::uint32_t kWantedComponents = 0xe7;

struct XsaveSetup {
    XsaveSetup() {
        unsigned a, b, c, d;
        if (!__get_cpuid(1, &a, &b, &c, &d)) return;
        const bool osxsave = c & (1u << 27);
        if (!osxsave) return;
        unsigned lo, hi;
        __asm__ volatile("xgetbv" : "=a"(lo), "=d"(hi) : "c"(0));
        const std::uint32_t mask = lo & kWantedComponents;
        std::uint32_t size = 576;  // legacy area + header
        for (unsigned i = 2; i < 8; ++i) {
            if (!(mask & (1u << i))) continue;
            __cpuid_count(0xd, i, a, b, c, d);
            if (a + b > size) size = a + b;  // size + standard-form offset
        }
        chm_port_xsave_mask = mask;
        chm_port_xsave_size = (size + 63) & ~63u;
    }
};
const XsaveSetup g_xsave_setup;

}  // namespace

std::uintptr_t interrupted_pc_from_signal(const void* ucontext) {
    return std::uintptr_t(static_cast<const ucontext_t*>(ucontext)->uc_mcontext.gregs[REG_RIP]);
}

std::uintptr_t interrupted_sp_from_signal(const void* ucontext) {
    return std::uintptr_t(static_cast<const ucontext_t*>(ucontext)->uc_mcontext.gregs[REG_RSP]);
}

void redirect_to_preempt_from_signal(void* ucontext) {
    greg_t* g = static_cast<ucontext_t*>(ucontext)->uc_mcontext.gregs;
    // Step over the 128-byte red zone, then "call" the trampoline: the
    // interrupted rip becomes its return address.
    auto* sp = reinterpret_cast<std::uint64_t*>(g[REG_RSP] - 128);
    *--sp = std::uint64_t(g[REG_RIP]);
    g[REG_RSP] = greg_t(sp);
    g[REG_RIP] = greg_t(&chm_port_preempt_trampoline);
}

}  // namespace chm::port
