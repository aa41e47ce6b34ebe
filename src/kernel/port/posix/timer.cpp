// The one timer of an RTPU process: a POSIX timer that sends a real-time
// signal to the kernel thread only (SIGEV_THREAD_ID). Its handler runs on an
// alternate signal stack, so no signal frame ever lands on a task stack.
#include "port.hpp"
#include "posix_internal.hpp"
#include "lib/hot.hpp"

#include <cerrno>
#include <csignal>
#include <cstdlib>
#include <ctime>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <sys/syscall.h>
#include <unistd.h>

namespace chm::port {

// initial-exec: no lazy TLS allocation inside the handler; read inline by
// on_kernel_thread (port.hpp).
constinit __attribute__((tls_model("initial-exec"))) thread_local bool t_kernel_thread = false;

namespace {

timer_t g_timer;
bool g_timer_live = false;
TickHandler g_tick = nullptr;
void* g_altstack = nullptr;
constexpr std::size_t kAltStackSize = 64 * 1024;
// 32-bit: 64-bit atomics take a lock on m68k, never in a signal handler.
std::uint32_t g_stray = 0;

std::uint32_t g_deferred = 0;
unsigned g_defer_streak = 0;  // consecutive deferrals: backs the retry off

CHM_HOT void on_timer(int, siginfo_t*, void* ucontext) {
    if (!t_kernel_thread) {  // a process-directed copy reached another thread
        __atomic_fetch_add(&g_stray, 1, __ATOMIC_RELAXED);
        return;
    }
    const int saved_errno = errno;
    if (g_irq.nest != 0) {
        irq_mark_pending(kPendingTick);
        doorbell_bump_from_signal();
    } else {
        g_irq.nest = 1;
        __atomic_signal_fence(__ATOMIC_SEQ_CST);
        const std::uint64_t now = now_exact_ns();  // judged against the clock that fired
        if (g_tick && g_tick(now)) {
#if CHM_PORT_HAS_PREEMPTION
            if (chm_port_preempt_hook &&
                preemptible_pc_from_signal(interrupted_pc_from_signal(ucontext))) {
                // The trampoline's frame goes below the interrupted sp: a
                // task too close to its guard page would fault inside it
                // with the mask held (a fail-stop of the whole RTPU).
                // Such a task is aborted as a stack overflow instead.
                const std::uintptr_t sp = interrupted_sp_from_signal(ucontext);
                const std::uintptr_t floor =
                    chm_port_preempt_floor_hook ? chm_port_preempt_floor_hook(sp) : 0;
                if (floor != 0 && (sp < floor || sp - floor < kPreemptFrameMax)) {
                    __atomic_signal_fence(__ATOMIC_SEQ_CST);
                    g_irq.nest = 0;  // as for a fault: the fault handler takes the mask
                    g_defer_streak = 0;
                    if (fault_no_room_from_signal(ucontext, sp - kPreemptFrameMax)) {
                        errno = saved_errno;
                        return;
                    }
                    g_irq.nest = 1;  // no fault handler: defer, as in foreign code
                    __atomic_signal_fence(__ATOMIC_SEQ_CST);
                } else {
                    // The task calls the hook itself after sigreturn; the
                    // mask stays held until the kernel releases it there.
                    redirect_to_preempt_from_signal(ucontext);
                    g_defer_streak = 0;
                    errno = saved_errno;
                    return;
                }
            }
#else
            (void)ucontext;
#endif
            // Inside the C library or another foreign object: keep the tick
            // pending (taken at the next irq_restore) and retry shortly. A
            // long library call (a big memset) backs the retry off, 20 µs
            // doubling up to 320 µs, so retries cannot eat the CPU when a
            // signal costs as much as the retry period (virtual machines).
            irq_mark_pending(kPendingTick);
            ++g_deferred;
            const unsigned shift = g_defer_streak < 4 ? g_defer_streak : 4;
            ++g_defer_streak;
            timer_arm_locked(now_ns() + (kPreemptRetryNs << shift));
        }
        __atomic_signal_fence(__ATOMIC_SEQ_CST);
        g_irq.nest = 0;
    }
    errno = saved_errno;
}

}  // namespace

int g_kernel_tid = 0;

int timer_signal() { return SIGRTMIN + 2; }

void set_kernel_thread(bool on) { t_kernel_thread = on; }
int kernel_pid() { return getpid(); }
int kernel_tid() { return g_kernel_tid; }

void irq_defer_pending_locked() {
    // A tick or a ring: the retry's tick dispatches either.
    irq_take_pending_bits();
    timer_arm_locked(now_ns() + kPreemptRetryNs);
}

std::uint64_t deferred_preemption_count() { return g_deferred; }

std::uint64_t stray_signal_count() { return __atomic_load_n(&g_stray, __ATOMIC_RELAXED); }

namespace {
long g_saved_slack = -1;  // the kernel thread's timer slack before timer_init
}  // namespace

int timer_init(TickHandler handler) {
    if (g_timer_live) return -EBUSY;
    g_tick = handler;
    preemptible_ranges_init();
    const int sig = timer_signal();

    if (!g_altstack) {
        g_altstack = mmap(nullptr, kAltStackSize, PROT_READ | PROT_WRITE,
                          MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
        if (g_altstack == MAP_FAILED) { g_altstack = nullptr; return -errno; }
    }
    stack_t ss{};
    ss.ss_sp = g_altstack;
    ss.ss_size = kAltStackSize;
    if (sigaltstack(&ss, nullptr) != 0) return -errno;

    struct sigaction sa{};
    sa.sa_sigaction = on_timer;
    sa.sa_flags = SA_SIGINFO | SA_ONSTACK | SA_RESTART;
    sigfillset(&sa.sa_mask);  // nothing nests inside the handler
    if (sigaction(sig, &sa, nullptr) != 0) return -errno;

    // The timer signals this thread only (SIGEV_THREAD_ID below). A copy
    // sent to the whole process that lands on another thread is counted and
    // ignored by the handler.
    sigset_t set;
    sigemptyset(&set);
    sigaddset(&set, sig);
    t_kernel_thread = true;
    pthread_sigmask(SIG_UNBLOCK, &set, nullptr);

    sigevent sev{};
    sev.sigev_notify = SIGEV_THREAD_ID;
    sev.sigev_signo = sig;
    g_kernel_tid = static_cast<int>(syscall(SYS_gettid));
    sev._sigev_un._tid = static_cast<pid_t>(g_kernel_tid);
    if (timer_create(CLOCK_MONOTONIC, &sev, &g_timer) != 0) return -errno;
    g_timer_live = true;
    // The idle loop's timed sleep ahead of an event (idle_wait_until_locked)
    // wakes when asked, not up to 50 µs later (the default slack).
    g_saved_slack = prctl(PR_GET_TIMERSLACK, 0, 0, 0, 0);
    (void)prctl(PR_SET_TIMERSLACK, 1, 0, 0, 0);
    return 0;
}

CHM_HOT void timer_arm_locked(std::uint64_t at_ns, std::uint64_t interval_ns) {
    if (!g_timer_live) return;
    itimerspec its{};
    if (at_ns != 0) {
        its.it_value.tv_sec = time_t(at_ns / 1000000000u);
        its.it_value.tv_nsec = long(at_ns % 1000000000u);
        its.it_interval.tv_sec = time_t(interval_ns / 1000000000u);
        its.it_interval.tv_nsec = long(interval_ns % 1000000000u);
    } else {
        interval_ns = 0;
    }
    g_timer_interval = interval_ns;
    ++g_timer_arms;
    timer_settime(g_timer, TIMER_ABSTIME, &its, nullptr);
}

void timer_fini() {
    if (!g_timer_live) return;
    timer_delete(g_timer);
    if (g_saved_slack > 0) (void)prctl(PR_SET_TIMERSLACK, g_saved_slack, 0, 0, 0);
    g_timer_live = false;
    g_timer_interval = 0;
    g_tick = nullptr;
    t_kernel_thread = false;
    g_kernel_tid = 0;
}

}  // namespace chm::port
