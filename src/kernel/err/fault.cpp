// Processor exceptions: the kernel's side. The port calls on_fault() on
// the kernel thread's alternate signal stack. A fault the kernel can pin on
// the running task is turned into an error signal of that task: the
// interrupted context is redirected into fault_entry(), which raises it in
// task context (a fault is never resumed: the entry ends in an abort or a
// return to a mark). After a stack overflow the task's own stack is
// exhausted, so the entry runs on one of a few fault stacks instead and
// the task can only be aborted. Anything else fail-stops the RTPU.
#include <cerrno>
#include <cstring>
#include <sys/mman.h>
#include <sys/syscall.h>
#include <unistd.h>

#include "err/err_internal.hpp"
#include "fault.hpp"
#include "port.hpp"

namespace chm::kernel {

namespace {

// Room the entry needs on a task's own stack (the default handler's line,
// a user handler); with less left it runs on a fault stack.
constexpr std::uintptr_t kEntryRoom = 4096;
// Room the preemption hook needs on the task's stack above the port's
// trampoline frame (kPreemptFrameMax): reschedule_locked and the switch
// frame, a few hundred bytes; a user scheduler's pick runs there too.
constexpr std::uintptr_t kPreemptHookRoom = 1024;
// The free-list link and the canary at the bottom of every task stack
// (task/stack.cpp): a preemption frame must not overwrite them either.
constexpr std::uintptr_t kStackBottomRoom = 16;
constexpr int kFaultStacks = 4;
constexpr std::size_t kFaultStackSize = 32 * 1024;

struct FaultStack {
    unsigned char* lo = nullptr;
    Tcb* owner = nullptr;  // the task running on it, until that task ends
};
FaultStack g_stacks[kFaultStacks];
std::size_t g_page = 4096;

// The fault being delivered: written by the handler, read by the entry,
// which starts with the mask held, so no second fault or switch comes in
// between.
struct Pending {
    Tcb* task;
    port::FaultInfo f;
    int code;
    bool on_fault_stack;
};
Pending g_pending;

int cpu_code(const port::FaultInfo& f) {
    switch (f.kind) {
    case port::FaultKind::Bus: return CHM_ECPU_BUS;
    case port::FaultKind::Arithmetic: return CHM_ECPU_FPE;
    case port::FaultKind::Illegal: return CHM_ECPU_ILL;
    default: return CHM_ECPU_SEGV;
    }
}

const char* cpu_message(int code) {
    switch (code) {
    case CHM_ECPU_BUS: return "bus error";
    case CHM_ECPU_FPE: return "arithmetic exception";
    case CHM_ECPU_ILL: return "illegal instruction";
    case CHM_ECPU_STACK: return "stack overflow";
    default: return "segmentation fault";
    }
}

[[noreturn]] void fail_stop(const port::FaultInfo& f, int code, Tcb* t, const char* where) {
    chm_err_info_t info{};
    info.module = CHM_ERR_CPU;
    info.code = code;
    info.module_name = "cpu";
    info.message = cpu_message(code);
    info.task = t ? tid_of(t) : CHM_TID_NONE;
    info.addr = f.addr;
    info.pc = f.pc;
    LineBuf b;
    b.put("chimera: RTPU ");
    b.num(err_rtpu());
    b.put(" FAIL-STOP: fault ");
    b.put(where);
    b.put("\n");
    (void)!syscall(SYS_write, 2, b.s, b.n);  // libc's write may be interposed (io/)
    LineBuf l;
    err_format_line(l, info, t ? t->name : nullptr);
    (void)!syscall(SYS_write, 2, l.s, l.n);
    _exit(CHM_ERR_FAILSTOP_STATUS);
}

// Raise the pending fault in the faulting task's context. Entered with the
// mask held (set by the handler); never returns.
void fault_entry() {
    const Pending p = g_pending;
    g_pending.task = nullptr;
    port::irq_restore();
    chm_err_info_t info{};
    info.module = CHM_ERR_CPU;
    info.code = p.code;
    info.detail = p.f.no_room                 ? "preempted with no room left on its stack"
                  : p.code == CHM_ECPU_STACK ? "the task overflowed its stack"
                                             : p.f.detail;
    info.flags = CHM_ERR_FATAL;
    info.addr = p.f.addr;
    info.pc = p.f.pc;
    info.status = -EFAULT;
    err_raise(info);  // a FATAL error never continues
    err_abort_current();
}

void on_fault(const port::FaultInfo& f, void* ucontext) {
    Tcb* cur = g_k.current;
    int code = cpu_code(f);
    if (!cur) fail_stop(f, code, nullptr, "on the kernel thread outside any task");
    if (port::g_irq.nest != 0) fail_stop(f, code, cur, "inside the kernel (interrupt mask held)");
    if (cur->err && cur->err->depth > 0) fail_stop(f, code, cur, "inside an error handler");
    const auto lo = reinterpret_cast<std::uintptr_t>(cur->stack_lo);
    const std::uintptr_t hi = lo + cur->stack_size;
    const bool guard_hit = f.kind == port::FaultKind::Access && f.addr < lo && f.addr + g_page >= lo;
    if (guard_hit || f.no_room || f.sp < lo || f.sp > hi) code = CHM_ECPU_STACK;
    std::uintptr_t sp = 0;  // 0: on the task's own stack, below the fault
    bool on_fault_stack = false;
    if (code == CHM_ECPU_STACK || f.sp < lo + kEntryRoom) {
        FaultStack* s = nullptr;
        for (auto& x : g_stacks)
            if (x.lo && !x.owner) {
                s = &x;
                break;
            }
        if (!s) fail_stop(f, code, cur, "with every fault stack in use");
        s->owner = cur;
        sp = reinterpret_cast<std::uintptr_t>(s->lo) + kFaultStackSize;
        on_fault_stack = true;
    }
    g_pending = Pending{cur, f, code, on_fault_stack};
    port::g_irq.nest = 1;  // released by fault_entry, as the preemption hook does
    __atomic_signal_fence(__ATOMIC_SEQ_CST);
    port::redirect_to_call_from_signal(ucontext, fault_entry, sp);
}

// The port's check before a preemption (chm_port_preempt_floor_hook):
// the lowest address the trampoline frame and the hook may reach on the
// stack the running task is on, its own or (inside an error handler after
// a fault) its fault stack. A stack pointer already inside the guard page
// below counts as that stack (no room at all). 0 (no check) outside any
// task and on a stack the kernel did not give out.
std::uintptr_t preempt_floor(std::uintptr_t sp) {
    const Tcb* cur = g_k.current;
    if (!cur || !cur->stack_lo) return 0;
    const auto lo = reinterpret_cast<std::uintptr_t>(cur->stack_lo);
    if (sp + g_page >= lo && sp <= lo + cur->stack_size)
        return lo + kStackBottomRoom + kPreemptHookRoom;
    for (const auto& x : g_stacks) {
        const auto flo = reinterpret_cast<std::uintptr_t>(x.lo);
        if (x.owner == cur && sp + g_page >= flo && sp <= flo + kFaultStackSize)
            return flo + kPreemptHookRoom;
    }
    return 0;
}

}  // namespace

bool err_on_fault_stack(const Tcb* t) {
    for (const auto& x : g_stacks)
        if (x.owner == t) return true;
    return false;
}

bool err_kernel_thread() { return port::on_fault_thread(); }

void err_fault_stack_release_locked(Tcb* t) {
    for (auto& x : g_stacks)
        if (x.owner == t) x.owner = nullptr;  // it is switched away for good
}

int err_kernel_init() {
    g_page = std::size_t(sysconf(_SC_PAGESIZE));
    for (auto& x : g_stacks) {
        x.owner = nullptr;
        if (x.lo) continue;
        // Kept for the process's life; a guard page below each.
        void* m = mmap(nullptr, kFaultStackSize + g_page, PROT_READ | PROT_WRITE,
                       MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
        if (m == MAP_FAILED) return -ENOMEM;
        mprotect(m, g_page, PROT_NONE);
        x.lo = static_cast<unsigned char*>(m) + g_page;
    }
    if (int e = port::fault_init(on_fault)) return e;
    port::chm_port_preempt_floor_hook = preempt_floor;
    return 0;
}

void err_kernel_fini() {
    port::chm_port_preempt_floor_hook = nullptr;
    port::fault_fini();
}

}  // namespace chm::kernel
