// Backplane wake-ups (ipc/wake/wake.hpp).
#include "ipc/wake/wake.hpp"

#include <cerrno>
#include <cstdint>
#include <ctime>
#include <linux/futex.h>
#include <sys/syscall.h>
#include <unistd.h>

#include "chimera/irq.h"
#include "ipc/backplane/backplane.hpp"
#include "kernel/sync/remote_wait.hpp"
#include "port.hpp"

namespace chm::ipc {

namespace {

std::uint32_t* word_of(bp::A32& a) { return reinterpret_cast<std::uint32_t*>(&a); }

port::Doorbell doorbell_of(bp::RtpuEntry* e) {
    return port::Doorbell{word_of(e->pending), word_of(e->mailbox), word_of(e->idle),
                          word_of(e->running),  word_of(e->urgency), true};
}

bool g_bound = false;

// A peer's kernel thread, through the identity check (bp::signal_member).
int interrupt_slot(void* ctx) {
    const auto slot = std::uint32_t(reinterpret_cast<std::uintptr_t>(ctx));
    return bp::signal_member(slot, bp::MemberTarget::KernelThread, port::timer_signal());
}
void* slot_ctx(std::uint32_t slot) { return reinterpret_cast<void*>(std::uintptr_t(slot)); }

void grant_vector(int, void*) { kernel::remote_scan_locked(); }

}  // namespace

int wake_bind_kernel() {
    bp::Attachment* a = bp::current();
    if (!a || a->kind != bp::SlotKind::Rtpu) return -ENOTCONN;
    if (!port::on_kernel_thread() || port::kernel_tid() == 0) return -EPERM;
    if (g_bound) return 0;
    bp::RtpuEntry* e = a->rtpu(a->slot);
    const port::Doorbell db = doorbell_of(e);
    port::irq_disable();
    port::doorbell_use(&db);
    kernel::publish_running_locked();
    port::irq_restore();
    e->tid.store(std::uint32_t(port::kernel_tid()));
    if (int r = chm_irq_install(kernel::kGrantVector, grant_vector, nullptr); r != 0 && r != -EBUSY)
        return r;
    g_bound = true;
    return 0;
}

void wake_unbind_kernel() {
    if (!g_bound) return;
    chm_irq_remove(kernel::kGrantVector);
    port::irq_disable();
    port::doorbell_use(nullptr);
    port::irq_restore();
    if (bp::Attachment* a = bp::current()) a->rtpu(a->slot)->tid.store(0);
    g_bound = false;
}

int wake_ring(std::uint32_t slot, int vector) {
    bp::Attachment* a = bp::current();
    if (!a) return -ENOTCONN;
    if (slot >= a->slots() || vector < 0 || vector >= CHM_IRQ_LINE_FIRST) return -EINVAL;
    bp::RtpuEntry* e = a->rtpu(slot);
    if (int(e->pid.load()) <= 0) return -ESRCH;
    // A refusal (the slot's pid or thread id is not the member's) is
    // reported by the check and returned, so a sender need not wait.
    struct Ctx {
        std::uint32_t slot;
        int result;
    } c{slot, 0};
    port::doorbell_ring(doorbell_of(e), 1u << vector, [](void* p) {
        Ctx& c = *static_cast<Ctx*>(p);
        return c.result = interrupt_slot(slot_ctx(c.slot));
    }, &c);
    return c.result == -EPERM ? -EPERM : 0;
}

int wait_word(std::uint32_t* word, std::int64_t timeout_ns) {
    if (kernel::remote_wait_possible()) return kernel::remote_wait(word, timeout_ns);
    // A host thread (or the kernel thread outside a task): the futex.
    timespec deadline{};
    if (timeout_ns >= 0) {
        clock_gettime(CLOCK_MONOTONIC, &deadline);
        const std::int64_t ns = deadline.tv_nsec + timeout_ns % 1000000000;
        deadline.tv_sec += time_t(timeout_ns / 1000000000 + ns / 1000000000);
        deadline.tv_nsec = long(ns % 1000000000);
    }
    while (!kernel::word_granted(__atomic_load_n(word, __ATOMIC_ACQUIRE))) {
        timespec left{};
        timespec* limit = nullptr;
        if (timeout_ns >= 0) {
            timespec now;
            clock_gettime(CLOCK_MONOTONIC, &now);
            std::int64_t d = (deadline.tv_sec - now.tv_sec) * 1000000000LL +
                             (deadline.tv_nsec - now.tv_nsec);
            if (d <= 0) return -ETIMEDOUT;
            left.tv_sec = time_t(d / 1000000000);
            left.tv_nsec = long(d % 1000000000);
            limit = &left;
        }
        const long r = syscall(SYS_futex, word, FUTEX_WAIT, 0, limit, nullptr, 0);
        if (r != 0 && errno == EINTR) return -EINTR;
    }
    return 0;
}

std::uint32_t wait_word_initial() { return kernel::remote_wait_initial_word(); }

bool waits_as_task() { return kernel::remote_wait_possible(); }

WaiterId waiter_self() {
    const std::uint32_t task = kernel::remote_waiter_id();
    return WaiterId{task, task ? kernel::remote_waiter_urgency() : UINT32_MAX};
}

bool store_grant(std::uint32_t* word, std::uint32_t value) {
    return __atomic_exchange_n(word, value, __ATOMIC_ACQ_REL) == kernel::kWordWatched;
}

void grant_word(std::uint32_t* word, std::uint32_t value, std::uint32_t slot, WaiterId who) {
    if (!store_grant(word, value)) wake_granted(word, slot, who);
}

void wake_granted(std::uint32_t* word, std::uint32_t slot, WaiterId who) {
    bp::Attachment* a = bp::current();
    bp::RtpuEntry* e = a && slot < a->slots() ? a->rtpu(slot) : nullptr;
    if (who.as_task() && e && e->tid.load() != 0) {
        if (slot == a->slot && port::on_kernel_thread()) {
            kernel::remote_scan();  // our own RTPU, from one of its tasks
        } else {
            port::doorbell_ring(doorbell_of(e), 1u << kernel::kGrantVector, interrupt_slot, slot_ctx(slot),
                                port::RingFor{who.urgency, who.task});
        }
        return;
    }
    syscall(SYS_futex, word, FUTEX_WAKE, 1, nullptr, nullptr, 0);  // a thread on the futex
}

}  // namespace chm::ipc
