// Idle: sleep on a futex word until the timer signal or a wake-up bumps it.
#include "port.hpp"
#include "posix_internal.hpp"

#include <linux/futex.h>
#include <sys/syscall.h>
#include <unistd.h>

namespace chm::port {

std::uint32_t g_wake_seq = 0;

void idle_wait_locked() {
    const std::uint32_t seen = __atomic_load_n(&g_wake_seq, __ATOMIC_ACQUIRE);
    if (g_irq.pending) return;
    // The timer handler bumps g_wake_seq when it records a pending tick, so a
    // tick between the test above and the sleep makes FUTEX_WAIT return at
    // once; one that arrives during the sleep interrupts it with EINTR.
    syscall(SYS_futex, &g_wake_seq, FUTEX_WAIT_PRIVATE, seen, nullptr, nullptr, 0);
}

void idle_wake() {
    __atomic_fetch_add(&g_wake_seq, 1, __ATOMIC_RELEASE);
    syscall(SYS_futex, &g_wake_seq, FUTEX_WAKE_PRIVATE, 1, nullptr, nullptr, 0);
}

}  // namespace chm::port
