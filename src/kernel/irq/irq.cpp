// Interrupts (chimera/irq.h): 32 mailbox vectors on the doorbell word, 32
// lines raised by threads of this process or by bound descriptors. One
// dispatcher delivers them in interrupt context, from the timer signal's
// handler, a tick taken at irq_restore, or the idle loop.
#include <cerrno>
#include <poll.h>

#include "chimera/irq.h"
#include "kernel.hpp"
#include "err/err_internal.hpp"
#include "lib/hot.hpp"

namespace chm::kernel {
namespace {

struct Vector {
    chm_irq_handler_t handler = nullptr;
    void* arg = nullptr;
    bool enabled = true;
    unsigned long count = 0;
    int fd = -1;  // lines only: the bound descriptor
    short events = 0;
};

Vector g_vec[CHM_IRQ_VECTORS];
// Lines raised by other threads (or signal handlers): bit = vector - 32.
std::uint32_t g_lines_raised = 0;
// Raised but not deliverable yet (disabled, or no handler). Mask held.
std::uint64_t g_held = 0;
int g_nfds = 0;  // bound descriptors

bool valid(int v) { return v >= 0 && v < CHM_IRQ_VECTORS; }

}  // namespace

void irq_dispatch_locked() {
    std::uint64_t raised = g_held | port::doorbell_take();
    if (__atomic_load_n(&g_lines_raised, __ATOMIC_RELAXED))
        raised |= std::uint64_t(__atomic_exchange_n(&g_lines_raised, 0, __ATOMIC_SEQ_CST)) << 32;
    g_held = 0;
    while (raised) {
        const int v = __builtin_ctzll(raised);
        raised &= raised - 1;
        Vector& x = g_vec[v];
        if (!x.handler || !x.enabled) {
            g_held |= std::uint64_t(1) << v;
            continue;
        }
        const bool nested = g_k.in_irq;
        g_k.in_irq = true;
        x.handler(v, x.arg);
        g_k.in_irq = nested;
        ++x.count;
    }
}

bool irq_fds_bound_locked() { return g_nfds > 0; }

CHM_HOT std::size_t irq_gather_fds_locked(pollfd* out, std::size_t room) {
    std::size_t k = 0;
    for (int v = CHM_IRQ_LINE_FIRST; v < CHM_IRQ_VECTORS && k < room; ++v) {
        const Vector& x = g_vec[v];
        if (x.fd < 0) continue;
        // A disabled line, or one already raised, needs no look.
        const bool quiet = !x.enabled || (g_held >> v & 1);
        out[k++] = pollfd{quiet ? -1 : x.fd, x.events, 0};
    }
    return k;
}

void irq_scatter_fds_locked(const pollfd* in, std::size_t n) {
    std::size_t k = 0;
    for (int v = CHM_IRQ_LINE_FIRST; v < CHM_IRQ_VECTORS && k < n; ++v) {
        if (g_vec[v].fd < 0) continue;
        if (in[k++].revents) g_held |= std::uint64_t(1) << v;
    }
}

void irq_reset() {
    for (Vector& x : g_vec) x = Vector{};
    g_held = 0;
    g_nfds = 0;
    __atomic_store_n(&g_lines_raised, 0, __ATOMIC_SEQ_CST);
    port::doorbell_take();
}

}  // namespace chm::kernel

using namespace chm::kernel;
namespace port = chm::port;

namespace {
// Deliver what just became deliverable, and let a task it readied run.
void deliver_now_locked() {
    irq_dispatch_locked();
    if (!g_k.in_irq) reschedule_locked();
}
}  // namespace

extern "C" {

int chm_irq_install(int vector, chm_irq_handler_t handler, void* arg) {
    if (!valid(vector) || !handler) return record_failure(-EINVAL, "chm_irq_install");
    if (!g_k.initialised) return record_failure(-EPERM, "chm_irq_install");
    IrqGuard guard;
    Vector& x = g_vec[vector];
    if (x.handler) return record_failure(-EBUSY, "chm_irq_install");
    x.handler = handler;
    x.arg = arg;
    x.enabled = true;
    deliver_now_locked();
    return 0;
}

int chm_irq_remove(int vector) {
    if (!valid(vector)) return record_failure(-EINVAL, "chm_irq_remove");
    IrqGuard guard;
    Vector& x = g_vec[vector];
    if (!x.handler) return record_failure(-ENOENT, "chm_irq_remove");
    if (x.fd >= 0) --g_nfds;
    x = Vector{};
    return 0;
}

int chm_irq_disable(int vector) {
    if (!valid(vector)) return record_failure(-EINVAL, "chm_irq_disable");
    IrqGuard guard;
    g_vec[vector].enabled = false;
    return 0;
}

int chm_irq_enable(int vector) {
    if (!valid(vector)) return record_failure(-EINVAL, "chm_irq_enable");
    IrqGuard guard;
    g_vec[vector].enabled = true;
    if (g_held >> vector & 1) deliver_now_locked();
    return 0;
}

// Off the kernel thread nothing is masked: the thread's own flag decides,
// so a lock and its unlock always agree.
void chm_irq_lock(void) {
    if (port::on_kernel_thread()) port::irq_disable();
}
void chm_irq_unlock(void) {
    if (port::on_kernel_thread()) port::irq_restore();
}

int chm_irq_raise(int vector) {
    if (!valid(vector)) return record_failure(-EINVAL, "chm_irq_raise");
    if (port::on_kernel_thread() && port::g_irq.nest == 0 && g_k.initialised) {
        // A task (or the kernel thread before run): deliver at once.
        IrqGuard guard;
        g_held |= std::uint64_t(1) << vector;
        deliver_now_locked();
        return 0;
    }
    if (vector < CHM_IRQ_LINE_FIRST) {
        port::doorbell_ring(port::doorbell(), 1u << vector, port::interrupt_own_kernel, nullptr);
    } else {
        __atomic_fetch_or(&g_lines_raised, 1u << (vector - CHM_IRQ_LINE_FIRST), __ATOMIC_SEQ_CST);
        port::doorbell_ring(port::doorbell(), 0, port::interrupt_own_kernel, nullptr);
    }
    return 0;
}

int chm_irq_attach_fd(int vector, int fd, short events) {
    if (vector < CHM_IRQ_LINE_FIRST || vector >= CHM_IRQ_VECTORS || fd < 0 || !events)
        return record_failure(-EINVAL, "chm_irq_attach_fd");
    IrqGuard guard;
    Vector& x = g_vec[vector];
    if (x.fd >= 0) return record_failure(-EBUSY, "chm_irq_attach_fd");
    if (g_nfds >= 32) return record_failure(-ENOSPC, "chm_irq_attach_fd");
    x.fd = fd;
    x.events = events;
    ++g_nfds;
    if (g_k.current) io_busy_arm_locked(now_locked());
    return 0;
}

int chm_irq_detach_fd(int vector) {
    if (vector < CHM_IRQ_LINE_FIRST || vector >= CHM_IRQ_VECTORS) return record_failure(-EINVAL, "chm_irq_detach_fd");
    IrqGuard guard;
    Vector& x = g_vec[vector];
    if (x.fd < 0) return record_failure(-ENOENT, "chm_irq_detach_fd");
    x.fd = -1;
    --g_nfds;
    g_held &= ~(std::uint64_t(1) << vector);
    return 0;
}

unsigned long chm_irq_count(int vector) { return valid(vector) ? g_vec[vector].count : 0; }

}  // extern "C"
