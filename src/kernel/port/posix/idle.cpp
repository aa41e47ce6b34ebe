// Idle: sleep on a futex word until the timer signal or a wake-up bumps it;
// with tasks parked in blocking UNIX calls, sleep in ppoll on their
// descriptors instead.
#include "port.hpp"
#include "posix_internal.hpp"

#include <csignal>
#include <ctime>
#include <linux/futex.h>
#include <poll.h>
#include <sys/syscall.h>
#include <unistd.h>

namespace chm::port {

std::uint32_t g_wake_seq = 0;

namespace {
// 1 while the kernel thread sleeps in ppoll: a futex wake cannot reach it
// there, so idle_wake() sends it the timer signal instead.
std::uint32_t g_idle_polling = 0;
}  // namespace

void idle_wait_locked() {
    const std::uint32_t seen = __atomic_load_n(&g_wake_seq, __ATOMIC_ACQUIRE);
    if (g_irq.pending) return;
    // The timer handler bumps g_wake_seq when it records a pending tick, so a
    // tick between the test above and the sleep makes FUTEX_WAIT return at
    // once; one that arrives during the sleep interrupts it with EINTR.
    syscall(SYS_futex, &g_wake_seq, FUTEX_WAIT_PRIVATE, seen, nullptr, nullptr, 0);
}

int idle_wait_fds_locked(pollfd* fds, unsigned long nfds, std::uint64_t until_ns) {
    const std::uint32_t seen = __atomic_load_n(&g_wake_seq, __ATOMIC_ACQUIRE);
    sigset_t block, during;
    sigemptyset(&block);
    sigaddset(&block, timer_signal());
    pthread_sigmask(SIG_BLOCK, &block, &during);
    sigdelset(&during, timer_signal());
    __atomic_store_n(&g_idle_polling, 1, __ATOMIC_SEQ_CST);
    int ready = 0;
    // A tick or wake() from here on is either seen by this test or kept
    // pending (signal blocked) until ppoll unblocks it atomically.
    if (!g_irq.pending && __atomic_load_n(&g_wake_seq, __ATOMIC_SEQ_CST) == seen) {
        timespec ts{};
        timespec* limit = nullptr;
        if (until_ns) {
            const std::uint64_t now = now_ns();
            const std::uint64_t left = until_ns > now ? until_ns - now : 0;
            ts.tv_sec = time_t(left / 1000000000u);
            ts.tv_nsec = long(left % 1000000000u);
            limit = &ts;
        }
        const int r = ppoll(fds, nfds, limit, &during);
        if (r > 0) ready = r;
    }
    __atomic_store_n(&g_idle_polling, 0, __ATOMIC_SEQ_CST);
    pthread_sigmask(SIG_UNBLOCK, &block, nullptr);
    return ready;
}

void idle_wake() {
    __atomic_fetch_add(&g_wake_seq, 1, __ATOMIC_SEQ_CST);
    if (__atomic_load_n(&g_idle_polling, __ATOMIC_SEQ_CST) && g_kernel_tid) {
        syscall(SYS_tgkill, getpid(), g_kernel_tid, timer_signal());
        return;
    }
    syscall(SYS_futex, &g_wake_seq, FUTEX_WAKE_PRIVATE, 1, nullptr, nullptr, 0);
}

}  // namespace chm::port
