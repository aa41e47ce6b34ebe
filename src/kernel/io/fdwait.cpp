// Parking tasks on file descriptors. A task whose UNIX call would block
// (io/blocking.cpp) waits here instead of blocking the kernel thread: the
// idle loop sleeps in ppoll on every parked descriptor, and while other
// tasks run an IoPoll timer polls them every cfg.io_poll_ns.
#include <cerrno>
#include <ctime>
#include <poll.h>

#include "chimera/io.h"
#include "kernel.hpp"
#include "err/err_internal.hpp"
#include "lib/hot.hpp"

namespace chm::kernel {

struct IoWait {
    pollfd* fds;
    nfds_t n;
};

namespace {

// One scratch array for every parked descriptor: built under the mask,
// also from the timer signal's handler, so it is static, not on a stack.
constexpr std::size_t kMaxPolled = 1024;
pollfd g_polled[kMaxPolled];

// poll(2) without the interposed wrapper (io/blocking.cpp), which would
// recurse here; ppoll is a plain system call, safe in the signal handler.
int poll_for(pollfd* fds, std::size_t n, std::uint64_t timeout_ns) {
    timespec ts{};
    timespec* limit = nullptr;
    if (timeout_ns != CHM_FOREVER) {
        ts.tv_sec = time_t(timeout_ns / 1000000000);
        ts.tv_nsec = long(timeout_ns % 1000000000);
        limit = &ts;
    }
    int r;
    // A look (timeout 0) interrupted by the RTPU's own timer signal is
    // taken again: ppoll never restarts, and that EINTR is not the caller's.
    do r = ::ppoll(fds, nfds_t(n), limit, nullptr);
    while (r < 0 && errno == EINTR && timeout_ns == 0);
    return r;
}

// Parked tasks' descriptors first, then the bound IRQ lines'.
std::size_t g_task_fds = 0;

std::size_t gather_locked() {
    std::size_t k = 0;
    for (Tcb* t = g_k.io_waiters.head; t; t = t->wnext) {
        for (nfds_t i = 0; i < t->io->n && k < kMaxPolled; ++i) {
            g_polled[k] = t->io->fds[i];
            g_polled[k].revents = 0;
            ++k;
        }
    }
    g_task_fds = k;
    return k + irq_gather_fds_locked(g_polled + k, kMaxPolled - k);
}

// Hand poll's results back to their tasks; wake each task with a ready one.
void scatter_locked() {
    std::size_t k = 0;
    Tcb* t = g_k.io_waiters.head;
    while (t) {
        Tcb* next = t->wnext;
        int ready = 0;
        for (nfds_t i = 0; i < t->io->n && k < kMaxPolled; ++i, ++k) {
            t->io->fds[i].revents = g_polled[k].revents;
            if (g_polled[k].revents) ++ready;
        }
        if (ready) wake_locked(t, ready);
        t = next;
    }
    irq_scatter_fds_locked(g_polled + g_task_fds, kMaxPolled - g_task_fds);
}

}  // namespace

void io_poll_locked() {
    const std::size_t n = gather_locked();
    if (n && poll_for(g_polled, n, 0) > 0) scatter_locked();
}

void io_tick_locked(std::uint64_t now) {
    io_poll_locked();
    irq_dispatch_locked();  // lines the poll raised
    if (io_watching_locked()) timer_add_locked(&g_k.io_tmr, now + g_k.cfg.io_poll_ns);
}

void io_busy_arm_locked(std::uint64_t now) {
    if (g_k.io_tmr.idx < 0 && !g_k.cfg.virtual_clock) {
        timer_add_locked(&g_k.io_tmr, now + g_k.cfg.io_poll_ns);
        timer_program_locked(now);
    }
}

CHM_HOT void io_idle_wait_locked() {
    // Idle: ppoll watches the descriptors itself; no polling timer.
    timer_cancel_locked(&g_k.io_tmr);
    const std::size_t n = gather_locked();
    if (g_k.cfg.virtual_clock) {
        // Virtual time stands still while the RTPU waits for the world; a
        // due virtual timer is taken after a look at the descriptors.
        if (next_due_locked()) {
            if (poll_for(g_polled, n, 0) > 0) {
                scatter_locked();
            } else {
                g_k.vnow = next_due_locked() > g_k.vnow ? next_due_locked() : g_k.vnow;
            }
            return;
        }
    } else {
        timer_program_locked(now_locked());
    }
    if (port::idle_wait_fds_locked(g_polled, n, 0) > 0) scatter_locked();
    // The idle loop's own path (time/clock.cpp): this one used to forget a
    // repeating timer (armed_at = 0) and re-arm it after every tick, a
    // timer_settime per cycle of a 1 kHz task on every chimera-rtpu.
    if (!g_k.cfg.virtual_clock && (port::irq_take_pending_bits() & port::kPendingTick)) idle_tick_locked();
}

}  // namespace chm::kernel

using namespace chm::kernel;
namespace port = chm::port;

extern "C" int chm_io_poll(struct pollfd* fds, unsigned long nfds, uint64_t timeout_ns) {
    if (!fds && nfds) return record_failure(-EFAULT, "chm_io_poll");
    if (nfds > kMaxPolled) return record_failure(-EINVAL, "chm_io_poll");
    for (unsigned long i = 0; i < nfds; ++i) fds[i].revents = 0;
    const int now_ready = poll_for(fds, nfds, 0);
    if (now_ready != 0 || timeout_ns == CHM_NO_WAIT) return now_ready < 0 ? -errno : now_ready;
    port::irq_disable();
    Tcb* cur = g_k.current;
    if (!cur || cur->lock_nest || !port::on_kernel_thread()) {
        // Not a task (or locked into the CPU): an ordinary blocking poll.
        port::irq_restore();
        const int r = poll_for(fds, nfds, timeout_ns);
        return r < 0 ? -errno : r;
    }
    IoWait w{fds, nfds_t(nfds)};
    cur->io = &w;
    cur->state = TaskState::Blocked;
    cur->interruptible = true;
    cur->wait_result = 0;
    waitq_insert_locked(&g_k.io_waiters, cur);
    const std::uint64_t now = now_locked();
    if (timeout_ns != CHM_FOREVER) {
        cur->tmr.kind = TimerKind::Wake;
        timer_add_locked(&cur->tmr, now + timeout_ns < now ? CHM_FOREVER : now + timeout_ns);
    }
    io_busy_arm_locked(now);
    timer_program_locked(now);
    int r = block_current_locked();
    cur->io = nullptr;
    deliver_pending_locked();
    port::irq_restore();
    if (r == -ETIMEDOUT) r = 0;  // poll's convention: nothing ready
    return r;
}
