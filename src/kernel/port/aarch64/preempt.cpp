// aarch64 side of the preemption contract: read a signal's ucontext and
// redirect it so the interrupted task calls the kernel itself, by way of a
// copy of the whole signal frame on the task's own stack.
//
// Why a copy: user code cannot restore every register and then jump to an
// arbitrary PC -- the jump needs a register (x16/x17 are only free at calls,
// x30 is live in leaf functions), and NZCV, FPSR and FPCR restores need one
// too. Only the kernel can, through rt_sigreturn. So the handler copies its
// frame (siginfo + ucontext, FP/SIMD record included) below the task's
// stack pointer and points the task at chm_port_preempt_trampoline; after
// the hook returns, the trampoline issues rt_sigreturn on that copy, which
// puts back every register, the flags, the FP state, the signal mask and
// the interrupted PC and SP at once.
#include "port.hpp"

#include <cstring>
#include <signal.h>
#include <ucontext.h>

extern "C" void chm_port_preempt_trampoline();

namespace chm::port {

namespace {

// The records of uc_mcontext.__reserved (Linux arm64 ABI,
// <asm/sigcontext.h>, which clashes with glibc's <signal.h> in C++).
struct RecordHead {
    std::uint32_t magic;
    std::uint32_t size;
};
struct ExtraContext {  // EXTRA_MAGIC: state that did not fit in __reserved
    RecordHead head;
    std::uint64_t datap;  // the extra space, contiguous with the frame
    std::uint32_t size;
    std::uint32_t reserved[3];
};
constexpr std::uint32_t kExtraMagic = 0x45585401;

// The rt_sigreturn frame: siginfo first, the ucontext right after it (the
// kernel finds the ucontext at sp + sizeof(siginfo_t)).
constexpr std::size_t kSiginfoSize = sizeof(siginfo_t);
static_assert(kSiginfoSize == 128 && sizeof(ucontext_t) == 4560,
              "the Linux arm64 rt_sigframe layout");
static_assert(kSiginfoSize + sizeof(ucontext_t) + 15 <= kPreemptFrameMax);

// The extra_context record of a frame, if the kernel had to use one (SVE or
// SME state too large for __reserved); nullptr on cores without it.
ExtraContext* find_extra(ucontext_t* uc) {
    auto* p = reinterpret_cast<unsigned char*>(uc->uc_mcontext.__reserved);
    const auto* end = p + sizeof uc->uc_mcontext.__reserved;
    while (p + sizeof(RecordHead) <= end) {
        auto* head = reinterpret_cast<RecordHead*>(p);
        if (head->magic == 0 || head->size < sizeof(RecordHead)) return nullptr;
        if (head->magic == kExtraMagic) return reinterpret_cast<ExtraContext*>(p);
        p += head->size;
    }
    return nullptr;
}

}  // namespace

std::uintptr_t interrupted_pc_from_signal(const void* ucontext) {
    return std::uintptr_t(static_cast<const ucontext_t*>(ucontext)->uc_mcontext.pc);
}

std::uintptr_t interrupted_sp_from_signal(const void* ucontext) {
    return std::uintptr_t(static_cast<const ucontext_t*>(ucontext)->uc_mcontext.sp);
}

void redirect_to_preempt_from_signal(void* ucontext) {
    auto* uc = static_cast<ucontext_t*>(ucontext);
    const auto uc_lo = reinterpret_cast<std::uintptr_t>(uc);
    // What to copy: the ucontext, and the extra space when there is one
    // (it follows the frame, possibly overlapping the unused tail of
    // __reserved). Without SVE/SME state this is just the ucontext.
    std::uintptr_t uc_hi = uc_lo + sizeof(ucontext_t);
    ExtraContext* extra = find_extra(uc);
    if (extra && extra->datap + extra->size > uc_hi) uc_hi = extra->datap + extra->size;
    const std::size_t span = uc_hi - uc_lo;

    // AAPCS64 has no red zone: everything below sp is free. The frame must
    // be 16-byte aligned (rt_sigreturn checks), and so stays the stack.
    const std::uintptr_t frame = (uc->uc_mcontext.sp - kSiginfoSize - span) & ~std::uintptr_t{15};
    auto* copy = reinterpret_cast<ucontext_t*>(frame + kSiginfoSize);
    __builtin_memcpy(copy, uc, span);
    if (extra) {
        // The copy's extra_context must point at the copy's extra space.
        auto* copy_extra = reinterpret_cast<ExtraContext*>(
            reinterpret_cast<std::uintptr_t>(extra) - uc_lo + frame + kSiginfoSize);
        copy_extra->datap = extra->datap - uc_lo + frame + kSiginfoSize;
    }
    // The siginfo half is never read by rt_sigreturn; leave it as it is.

    uc->uc_mcontext.sp = frame;
    uc->uc_mcontext.pc = reinterpret_cast<std::uintptr_t>(&chm_port_preempt_trampoline);
}

}  // namespace chm::port
