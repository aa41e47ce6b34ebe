// The robust backplane lock. The lock word is the holder's token (slot and
// generation), set by one compare-and-swap, so "locked" and "by whom" can
// never disagree: a holder killed at any instruction leaves either a free
// lock or one that names it. A waiter that finds the named holder dead (its
// slot no longer RUNNING with that generation, or its process gone) robs
// the lock with a CAS from exactly that token and learns it did
// (-EOWNERDEAD), together with the holder's dirty flag.
//
// Why not the port's byte tas(): a byte can say "taken" but not by whom,
// and a holder dying between its tas and writing its name would leave a
// lock nobody can ever prove abandoned. The 32-bit CAS is the same single
// indivisible read-modify-write bus cycle (`cas.l` on the 68020+,
// `lock cmpxchg` on x86-64), it just carries the owner's name with it.
#include <cerrno>
#include <cstdio>

#include <unistd.h>

#include "ipc/backplane/backplane.hpp"
#include "kernel/task/holds.hpp"
#include "port.hpp"

namespace chm::bp {

bool slot_holder_dead(const View& v, std::uint32_t slot, std::uint32_t st) {
    const RtpuEntry* e = v.rtpu(slot);
    switch (status_state(st)) {
    case SlotState::Joining: {
        const std::uint32_t p = e->pid.load(std::memory_order_acquire);
        if (p == vacant_pid(status_gen(st))) return true;  // given up (joining_abandon)
        if (!pid_named(p)) return false;  // not named yet: only joining_abandon may judge it
        return !proc_alive(int(p), e->pid_start.load());
    }
    case SlotState::Running:
    case SlotState::Leaving: {
        const std::uint32_t p = e->pid.load(std::memory_order_relaxed);
        return !pid_named(p) || !proc_alive(int(p), e->pid_start.load());
    }
    case SlotState::Recovering:
        return !recoverer_alive(e->recoverer.load(std::memory_order_acquire));
    default:
        return true;
    }
}

bool joining_abandon(const View& v, std::uint32_t slot, std::uint32_t st, std::uint32_t pid) {
    RtpuEntry* e = v.rtpu(slot);
    if (status_state(st) != SlotState::Joining) return false;
    // Both words unchanged since the caller saw them: the pid it read lies
    // inside this JOINING generation (gens only grow), so the CAS below
    // cannot land in a later one.
    if (e->status.load(std::memory_order_acquire) != st || e->pid.load(std::memory_order_acquire) != pid)
        return false;
    const std::uint32_t vacated = vacant_pid(status_gen(st));
    if (pid == vacated) return true;
    if (pid_named(pid)) return !proc_alive(int(pid), e->pid_start.load());
    std::uint32_t expect = pid;
    return e->pid.compare_exchange_strong(expect, vacated, std::memory_order_acq_rel);
}

bool token_alive(const View& v, std::uint32_t token, bool deep) {
    const std::uint32_t slot = token_slot(token);
    if (token == 0) return true;
    if (slot >= v.slots()) return false;  // garbage: nobody can hold it
    const std::uint32_t st = v.rtpu(slot)->status.load(std::memory_order_acquire);
    if ((status_gen(st) & kGenMask) != token_gen(token)) return false;
    const SlotState s = status_state(st);
    const bool live = token_recovery(token)
                          ? s == SlotState::Recovering
                          : (s == SlotState::Joining || s == SlotState::Running || s == SlotState::Leaving);
    if (!live) return false;
    return deep ? !slot_holder_dead(v, slot, st) : true;
}

// Task `task` ended holding `l` (its hold list, kernel/task/holds.hpp):
// a lock it left clean is released; one it left dirty (mid-change) gets
// the orphan token, which no slot can own, so the next user robs it at
// once (-EOWNERDEAD with the dirty flag) and repairs the object exactly
// as for a dead process. Nothing is done unless the lock still names the
// task (another task of the RTPU may have unlocked a user spin-lock and
// taken it again). Any context, no waiting.
static void release_abandoned(void* p, std::uint32_t task) {
    Lock* l = static_cast<Lock*>(p);
    std::uint32_t t = l->token.load(std::memory_order_acquire);
    if (t == 0 || t == kOrphanToken || l->owner_task.load(std::memory_order_relaxed) != task) return;
    if (l->dirty.load(std::memory_order_acquire)) {
        (void)l->token.compare_exchange_strong(t, kOrphanToken, std::memory_order_release);
        return;
    }
    l->owner_task.store(0, std::memory_order_relaxed);
    (void)l->token.compare_exchange_strong(t, 0, std::memory_order_release);
}

static int take(Lock* l, std::uint32_t expected, std::uint32_t me) {
    if (!l->token.compare_exchange_strong(expected, me, std::memory_order_acquire,
                                          std::memory_order_relaxed))
        return -EBUSY;
    const std::uint32_t task = task_word();
    l->owner_task.store(task, std::memory_order_relaxed);
    (void)kernel::hold_add(release_abandoned, l, task);  // a task's: given back however it ends
    return 0;
}

int lock_try(const View& v, Lock* l, std::uint32_t me) {
    const std::uint32_t t = l->token.load(std::memory_order_relaxed);
    if (t == 0) return take(l, 0, me);
    if (!token_alive(v, t, false) && take(l, t, me) == 0) return -EOWNERDEAD;
    return -EBUSY;
}

bool masked_wait() { return port::on_kernel_thread() && port::irq_masked(); }

int lock_acquire_brief(const View& v, Lock* l, std::uint32_t me, std::uint64_t spin_ns) {
    if (take(l, 0, me) == 0) return 0;
    const std::uint64_t start = port::now_ns();
    for (unsigned spins = 1;; ++spins) {
        const std::uint32_t t = l->token.load(std::memory_order_relaxed);
        if (t == 0) {
            if (take(l, 0, me) == 0) return 0;
            continue;
        }
        if (spins & 63) {
            port::relax();
            continue;
        }
        const bool last = port::now_ns() - start >= spin_ns;
        // The kernel is asked only once, at the end: it reads /proc.
        if (!token_alive(v, t, last) && take(l, t, me) == 0) return -EOWNERDEAD;
        if (last) return -EBUSY;
    }
}

int lock_holder(const Lock* l, char* out, std::size_t n) {
    const std::uint32_t t = l->token.load(std::memory_order_relaxed);
    const std::uint32_t who = l->owner_task.load(std::memory_order_relaxed);
    if (t == 0) return std::snprintf(out, n, "nobody");
    if (who & 0x80000000u)
        return std::snprintf(out, n, "slot %u (thread %u)", unsigned(token_slot(t)), unsigned(who & 0x7fffffffu));
    return std::snprintf(out, n, "slot %u (task %u)", unsigned(token_slot(t)), unsigned(who));
}

namespace {
thread_local const WaitBound* t_bound = nullptr;  // the innermost scope
}  // namespace

WaitBound::WaitBound(std::uint64_t budget_ns, const std::atomic<bool>* cancel)
    : deadline_ns(0), cancel(cancel), outer(t_bound) {
    const std::uint64_t now = port::now_ns();
    deadline_ns = budget_ns > UINT64_MAX - now ? UINT64_MAX : now + budget_ns;
    if (outer && outer->deadline_ns < deadline_ns) deadline_ns = outer->deadline_ns;
    if (outer && !this->cancel) this->cancel = outer->cancel;
    t_bound = this;
}
WaitBound::~WaitBound() { t_bound = outer; }

bool WaitBound::over() {
    const WaitBound* b = t_bound;
    if (!b) return false;
    return (b->cancel && b->cancel->load(std::memory_order_relaxed)) || port::now_ns() >= b->deadline_ns;
}

int lock_acquire(const View& v, Lock* l, std::uint32_t me, std::uint64_t poll_ns,
                 std::uint64_t timeout_ns) {
    if (take(l, 0, me) == 0) return 0;  // the uncontended path: one CAS
    if (poll_ns == 0) poll_ns = 10'000;
    const std::uint64_t start = port::now_ns();
    if (const WaitBound* b = t_bound) {  // the thread's scope may end the wait sooner
        const std::uint64_t left = b->deadline_ns > start ? b->deadline_ns - start : 0;
        if (left < timeout_ns) timeout_ns = left;
    }
    // With the interrupt mask held (an interrupt handler, a chm_irq_lock
    // section) nothing else of this RTPU runs while we spin, and nothing
    // may block: the wait is cut to a try's.
    const bool masked = masked_wait();
    if (masked && timeout_ns > kTryLockNs) timeout_ns = kTryLockNs;
    std::uint64_t next_deep = start + 10'000'000;  // ask the kernel about the holder every 10 ms
    for (unsigned spins = 0;; ++spins) {
        const std::uint32_t t = l->token.load(std::memory_order_relaxed);
        if (t == 0) {
            if (take(l, 0, me) == 0) return 0;
            continue;
        }
        // Cheap check every round; the process check only now and then
        // (it reads /proc). The monitor threads usually get there first
        // and turn the slot RECOVERING, which the cheap check sees.
        const bool busy_phase = (spins & 63) != 0;
        if (busy_phase) {
            port::relax();
            continue;
        }
        const std::uint64_t now = port::now_ns();
        const bool deep = now >= next_deep;
        if (deep) next_deep = now + 10'000'000;
        if (!token_alive(v, t, deep) && take(l, t, me) == 0) return -EOWNERDEAD;
        if (timeout_ns != UINT64_MAX && now - start >= timeout_ns) return -ETIMEDOUT;
        if (t_bound && t_bound->cancel && t_bound->cancel->load(std::memory_order_relaxed)) return -ETIMEDOUT;
        // Within the first polling interval, spin; after it, test once per
        // interval and give the CPU away in between.
        if (now - start >= poll_ns && !masked) {
            std::uint64_t nap = poll_ns;
            if (timeout_ns != UINT64_MAX && now - start + nap > timeout_ns) nap = timeout_ns - (now - start);
            relinquish(nap ? nap : 1);
        }
    }
}

int lock_acquire_recovery(const View& v, Lock* l, std::uint32_t rt) {
    if (l->token.load(std::memory_order_acquire) == rt) return -EOWNERDEAD;
    return lock_acquire(v, l, rt, kInternalPollNs, kInternalTimeoutNs);
}

void lock_release(Lock* l) {
    kernel::hold_drop(l);
    l->owner_task.store(0, std::memory_order_relaxed);
    l->token.store(0, std::memory_order_release);
}

void lock_mark_dirty(Lock* l) {
    l->dirty.store(1, std::memory_order_relaxed);
    // The flag is visible before any change it announces.
    std::atomic_thread_fence(std::memory_order_release);
}

void lock_clear_dirty(Lock* l) { l->dirty.store(0, std::memory_order_release); }

}  // namespace chm::bp
