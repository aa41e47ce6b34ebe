// Processor exceptions on POSIX: SIGSEGV, SIGBUS, SIGFPE and SIGILL of the
// kernel thread go to the kernel's fault handler on the alternate signal
// stack (a stack overflow leaves the task stack unusable, so the handler
// could not run on it); other threads keep the action found at install.
#include "fault.hpp"

#include <cerrno>
#include <csignal>
#include <sys/mman.h>

#include "port.hpp"

namespace chm::port {

namespace {

constexpr int kSignals[] = {SIGSEGV, SIGBUS, SIGFPE, SIGILL};
constexpr std::size_t kAltStackSize = 64 * 1024;

FaultHandler g_handler = nullptr;
struct sigaction g_old[4];
bool g_installed = false;
void* g_altstack = nullptr;
__attribute__((tls_model("initial-exec"))) thread_local bool t_fault_thread = false;

int index_of(int sig) {
    for (int i = 0; i < 4; ++i)
        if (kSignals[i] == sig) return i;
    return 0;
}

FaultKind kind_of(int sig) {
    switch (sig) {
    case SIGBUS: return FaultKind::Bus;
    case SIGFPE: return FaultKind::Arithmetic;
    case SIGILL: return FaultKind::Illegal;
    default: return FaultKind::Access;
    }
}

// What si_code says about the cause (FaultInfo::detail).
const char* detail_of(int sig, int code) {
    if (code <= 0) return "signal sent by a process";
    switch (sig) {
    case SIGSEGV:
        return code == SEGV_MAPERR ? "address not mapped" : code == SEGV_ACCERR ? "access not permitted" : nullptr;
    case SIGBUS:
        return code == BUS_ADRALN ? "misaligned address" : code == BUS_ADRERR ? "no such physical address" : nullptr;
    case SIGFPE:
        switch (code) {
        case FPE_INTDIV: return "integer division by zero";
        case FPE_INTOVF: return "integer overflow";
        case FPE_FLTDIV: return "floating-point division by zero";
        case FPE_FLTOVF: return "floating-point overflow";
        case FPE_FLTINV: return "invalid floating-point operation";
        default: return nullptr;
        }
    case SIGILL:
        return code == ILL_ILLOPC ? "illegal opcode" : code == ILL_PRVOPC ? "privileged opcode" : nullptr;
    default:
        return nullptr;
    }
}

// A fault that is not ours: what would have happened without us.
void chain(int sig, siginfo_t* si, void* uc) {
    const struct sigaction& old = g_old[index_of(sig)];
    if ((old.sa_flags & SA_SIGINFO) && old.sa_sigaction) {
        old.sa_sigaction(sig, si, uc);
        return;
    }
    if (old.sa_handler != SIG_DFL && old.sa_handler != SIG_IGN) {
        old.sa_handler(sig);
        return;
    }
    // Default action: restore it; a processor fault recurs on return and
    // kills the process as usual, a sent one is sent again.
    signal(sig, SIG_DFL);
    if (si->si_code <= 0) raise(sig);
}

void on_fault(int sig, siginfo_t* si, void* uc) {
    if (!t_fault_thread || !g_handler) {
        chain(sig, si, uc);
        return;
    }
    const int saved_errno = errno;
    FaultInfo f{kind_of(sig), detail_of(sig, si->si_code), reinterpret_cast<std::uintptr_t>(si->si_addr),
                interrupted_pc_from_signal(uc), interrupted_sp_from_signal(uc)};
    g_handler(f, uc);
    errno = saved_errno;
}

}  // namespace

bool on_fault_thread() { return t_fault_thread; }

bool fault_no_room_from_signal(void* ucontext, std::uintptr_t addr) {
    if (!t_fault_thread || !g_handler) return false;
    FaultInfo f{FaultKind::Access, detail_of(SIGSEGV, 0), addr, interrupted_pc_from_signal(ucontext),
                interrupted_sp_from_signal(ucontext), true};
    g_handler(f, ucontext);
    return true;
}

int fault_init(FaultHandler handler) {
    stack_t cur{};
    if (sigaltstack(nullptr, &cur) != 0) return -errno;
    if ((cur.ss_flags & SS_DISABLE) || cur.ss_size < kAltStackSize / 2) {
        if (!g_altstack) {
            void* m = mmap(nullptr, kAltStackSize, PROT_READ | PROT_WRITE,
                           MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
            if (m == MAP_FAILED) return -errno;
            g_altstack = m;
        }
        stack_t ss{};
        ss.ss_sp = g_altstack;
        ss.ss_size = kAltStackSize;
        if (sigaltstack(&ss, nullptr) != 0) return -errno;
    }
    g_handler = handler;
    t_fault_thread = true;
    if (g_installed) return 0;
    struct sigaction sa{};
    sa.sa_sigaction = on_fault;
    sa.sa_flags = SA_SIGINFO | SA_ONSTACK;
    sigfillset(&sa.sa_mask);  // the timer never lands in the middle
    for (int i = 0; i < 4; ++i) {
        if (sigaction(kSignals[i], &sa, &g_old[i]) != 0) {
            const int e = errno;
            while (--i >= 0) sigaction(kSignals[i], &g_old[i], nullptr);
            return -e;
        }
    }
    g_installed = true;
    return 0;
}

void fault_fini() {
    if (g_installed) {
        for (int i = 0; i < 4; ++i) sigaction(kSignals[i], &g_old[i], nullptr);
        g_installed = false;
    }
    g_handler = nullptr;
    t_fault_thread = false;
}

}  // namespace chm::port
