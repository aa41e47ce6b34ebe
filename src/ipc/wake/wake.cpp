// Backplane wake-ups (ipc/wake/wake.hpp).
#include "ipc/wake/wake.hpp"

#include <cerrno>
#include <cstdint>
#include <ctime>
#include <linux/futex.h>
#include <sys/syscall.h>
#include <unistd.h>

#include "chimera/irq.h"
#include "chimera/kernel.h"
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
    (void)chm_irq_remove(kernel::kGrantVector);
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

std::uint64_t wait_now() { return kernel::remote_wait_possible() ? chm_time_now() : port::now_ns(); }

WaitLimit wait_for(std::uint64_t timeout_ns) {
    if (timeout_ns == CHM_NO_WAIT) return WaitLimit{WaitLimit::kNoWait, 0};
    if (timeout_ns == CHM_FOREVER) return WaitLimit{WaitLimit::kForever, 0};
    return WaitLimit{WaitLimit::kFor, timeout_ns};
}

WaitLimit wait_until(std::uint64_t deadline_ns) {
    if (deadline_ns == CHM_FOREVER) return WaitLimit{WaitLimit::kForever, 0};
    return WaitLimit{WaitLimit::kUntil, deadline_ns};
}

std::uint64_t WaitLimit::lock_budget(std::uint64_t cap, bool* own) const {
    std::uint64_t left = cap;
    if (kind == kNoWait) left = 0;
    if (kind == kFor) left = ns;
    if (kind == kUntil) {
        const std::uint64_t now = chm_time_now();
        left = ns > now ? ns - now : 0;
    }
    if (own) *own = kind != kForever && left < cap;
    return left < cap ? left : cap;
}

std::uint64_t WaitLimit::deadline() const {
    switch (kind) {
    case kForever: return CHM_FOREVER;
    case kNoWait: return 0;  // already past
    case kFor: {
        const std::uint64_t now = wait_now();
        return now + ns < now ? CHM_FOREVER : now + ns;
    }
    case kUntil: break;
    }
    // A deadline on chm_time_now()'s clock. A parked task waits on that
    // very clock: exact, on the virtual clock too. Another thread sleeps
    // on CLOCK_MONOTONIC, which is chm_time_now()'s clock unless this
    // process's kernel runs a virtual clock; then (virtual time does not
    // pass for a thread that is no task) the time left at entry is waited
    // on the monotonic clock, computed once: both clocks are monotonic, so
    // the wait neither ends early nor is stretched by a clock step.
    if (kernel::remote_wait_possible() || !kernel::clock_is_virtual()) return ns;
    const std::uint64_t now = chm_time_now();
    if (ns <= now) return 0;  // already past: no wait
    const std::uint64_t mono = port::now_ns(), left = ns - now;
    return mono + left < mono ? CHM_FOREVER : mono + left;
}

int wait_word(std::uint32_t* word, std::uint64_t deadline) {
    if (kernel::remote_wait_possible()) return kernel::remote_wait(word, deadline);
    // A host thread (or the kernel thread outside a task): the futex,
    // CLOCK_MONOTONIC (port::now_ns), the time left recomputed each round.
    while (!kernel::word_granted(__atomic_load_n(word, __ATOMIC_ACQUIRE))) {
        timespec left{};
        timespec* limit = nullptr;
        if (deadline != CHM_FOREVER) {
            const std::uint64_t now = port::now_ns();
            if (now >= deadline) return -ETIMEDOUT;
            const std::uint64_t d = deadline - now;
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
    // Our own RTPU, from one of its tasks: scan its parked tasks. Bound or
    // not (a virtual-clock kernel has no thread for peers to signal, so it
    // is not bound, but its own tasks wake each other).
    if (who.as_task() && e && slot == a->slot && port::on_kernel_thread()) return kernel::remote_scan();
    if (who.as_task() && e && e->tid.load() != 0) {
        port::doorbell_ring(doorbell_of(e), 1u << kernel::kGrantVector, interrupt_slot, slot_ctx(slot),
                            port::RingFor{who.urgency, who.task});
        return;
    }
    syscall(SYS_futex, word, FUTEX_WAKE, 1, nullptr, nullptr, 0);  // a thread on the futex
}

}  // namespace chm::ipc
