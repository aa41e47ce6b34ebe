// Idle and the doorbell: the kernel thread sleeps on the doorbell's futex
// word until the timer signal or a ring bumps it; with tasks parked in
// blocking UNIX calls it sleeps in ppoll on their descriptors instead, and
// a ring reaches it by a directed signal.
#include "port.hpp"
#include "posix_internal.hpp"
#include "lib/hot.hpp"

#include <cerrno>
#include <csignal>
#include <ctime>
#include <linux/futex.h>
#include <poll.h>
#include <sys/syscall.h>
#include <unistd.h>

namespace chm::port {

namespace {

std::uint32_t g_own_pending = 0, g_own_seq = 0, g_own_state = kDbRunning;
const Doorbell kOwnDoorbell{&g_own_pending, &g_own_seq, &g_own_state, nullptr, nullptr, false};
Doorbell g_db = kOwnDoorbell;
std::uint32_t g_rings_sent = 0, g_signals_sent = 0;  // 32-bit: a 64-bit atomic is a libatomic call on m68k
// What this RTPU last published (its own copy: no read of the shared line).
std::uint32_t g_published_running = 0, g_published_urgency = 0;

std::uint32_t load(const std::uint32_t* w) { return __atomic_load_n(w, __ATOMIC_SEQ_CST); }
void store(std::uint32_t* w, std::uint32_t v) { __atomic_store_n(w, v, __ATOMIC_SEQ_CST); }

void futex(std::uint32_t* w, int op, std::uint32_t val, bool shared) {
    syscall(SYS_futex, w, shared ? op : (op | FUTEX_PRIVATE_FLAG), val, nullptr, nullptr, 0);
}

}  // namespace

CHM_HOT void doorbell_bump_from_signal() { __atomic_fetch_add(g_db.seq, 1, __ATOMIC_SEQ_CST); }

void doorbell_use(const Doorbell* db) {
    const std::uint32_t moved = __atomic_exchange_n(g_db.pending, 0, __ATOMIC_SEQ_CST);
    g_db = db ? *db : kOwnDoorbell;
    g_db_publishes = g_db.running && g_db.urgency;
    if (g_db_publishes) {
        // Nothing known yet: every ring interrupts until the kernel publishes.
        g_published_running = kRunningUnknown;
        g_published_urgency = 0;
        store(g_db.urgency, 0);
        store(g_db.running, kRunningUnknown);
    }
    store(g_db.state, kDbRunning);
    if (moved) __atomic_fetch_or(g_db.pending, moved, __ATOMIC_SEQ_CST);
}

CHM_HOT void doorbell_publish_locked(std::uint32_t running, std::uint32_t urgency) {
    if (!g_db_publishes) return;
    if (running != g_published_running || urgency != g_published_urgency) {
        const bool may_matter = running != g_published_running || urgency < g_published_urgency;
        g_published_running = running;
        g_published_urgency = urgency;
        __atomic_store_n(g_db.urgency, urgency, __ATOMIC_RELAXED);
        if (!may_matter) {
            __atomic_store_n(g_db.running, running, __ATOMIC_RELEASE);
            return;
        }
        // Against doorbell_ring: it sets `pending` then reads what we
        // publish; we publish then read `pending`. One of the two sees the
        // other, so a ring that skipped its signal for the task we leave is
        // taken below.
        store(g_db.running, running);
    }
    // Reached too when nothing changed: the scheduler ran without a switch,
    // and a task's order may have changed (a priority set or lent, MUF's
    // critical set), a waiter's too, past the number its record holds. A
    // ring left without a signal is taken now rather than at the next
    // switch. (To the idle loop, running 0: it dispatches `pending` itself.)
    if (running && load(g_db.pending)) irq_mark_pending(kPendingRing);
}

const Doorbell& doorbell() { return g_db; }

bool doorbell_raised() { return load(g_db.pending) != 0; }

std::uint32_t doorbell_take() {
    if (!load(g_db.pending)) return 0;  // the common case: no atomic write
    return __atomic_exchange_n(g_db.pending, 0, __ATOMIC_SEQ_CST);
}

int interrupt_own_kernel(void*) {
    // Our own kernel thread, named by process memory (never by a file).
    if (g_kernel_tid <= 0) return -ESRCH;
    return syscall(SYS_tgkill, getpid(), g_kernel_tid, timer_signal()) == 0 ? 0 : -errno;
}

void doorbell_ring(const Doorbell& db, std::uint32_t bits, Interrupt interrupt, void* ctx, RingFor why) {
    if (bits) {
        __atomic_fetch_or(db.pending, bits, __ATOMIC_SEQ_CST);
        __atomic_fetch_add(&g_rings_sent, 1, __ATOMIC_RELAXED);
    }
    __atomic_fetch_add(db.seq, 1, __ATOMIC_SEQ_CST);
    switch (load(db.state)) {
    case kDbSleeping:
        futex(db.seq, FUTEX_WAKE, 1, db.shared);
        break;
    case kDbPolling:
        break;  // it sees `pending` or `seq` change within its poll
    case kDbRunning:
        // It runs the very task we wake, or one at least as urgent: the
        // vector waits for its next switch (doorbell_publish_locked).
        if (bits && db.running && db.urgency) {
            const std::uint32_t running = load(db.running);
            if (running == 0) break;  // between tasks: it looks at `pending` first
            if (running != kRunningUnknown &&
                (why.task == running || why.urgency <= load(db.urgency)))
                break;
        }
        [[fallthrough]];
    default:  // asleep in ppoll, or running something less urgent: interrupt it
        if (interrupt(ctx) == 0) __atomic_fetch_add(&g_signals_sent, 1, __ATOMIC_RELAXED);
        break;
    }
}

std::uint32_t doorbell_rings_sent() { return __atomic_load_n(&g_rings_sent, __ATOMIC_RELAXED); }
std::uint32_t doorbell_signals_sent() { return __atomic_load_n(&g_signals_sent, __ATOMIC_RELAXED); }

void idle_wait_locked(std::uint64_t poll_ns, const IdleWatch* watch) {
    const std::uint32_t seen = load(g_db.seq);
    if (g_irq.pending || load(g_db.pending)) return;
    if (poll_ns) {
        // Stay in user space a little: a ring from a busy peer, or a grant
        // to a watched word, then costs no system call on either side.
        store(g_db.state, kDbPolling);
        bool woke = watch && watch->begin();
        const std::uint64_t end = now_ns() + poll_ns;
        for (unsigned n = 0; !woke && load(g_db.seq) == seen && !g_irq.pending; ++n) {
            if (watch && watch->woken()) break;
            if ((n & 15) == 0 && now_ns() >= end) break;
            relax();
        }
        // Unwatched before any sleep: a grant from here on rings.
        if (watch && watch->end()) woke = true;
        if (woke) return store(g_db.state, kDbRunning);
    }
    store(g_db.state, kDbSleeping);
    // The timer handler and every ring bump `seq`, so one that comes after
    // `seen` was read makes FUTEX_WAIT return at once; one during the sleep
    // wakes it (a ring) or interrupts it with EINTR (the timer).
    if (load(g_db.seq) == seen && !g_irq.pending) futex(g_db.seq, FUTEX_WAIT, seen, g_db.shared);
    store(g_db.state, kDbRunning);
}

namespace {

// Poll the doorbell until `end` (now_ns()): true when it came, false on a
// ring or tick since `seen`. A ring while polling bumps `seq` and makes
// no system call (doorbell_ring).
bool poll_doorbell_until(std::uint32_t seen, std::uint64_t end) {
    store(g_db.state, kDbPolling);
    for (unsigned n = 0;; ++n) {
        if (load(g_db.seq) != seen || g_irq.pending) return false;
        if ((n & 15) == 0 && now_ns() >= end) return true;
        relax();
    }
}

}  // namespace

IdleEnd idle_sleep_until_locked(std::uint64_t poll_ns, std::uint64_t wake_ns, std::uint64_t* woke_late) {
    *woke_late = UINT64_MAX;
    const std::uint32_t seen = load(g_db.seq);
    if (g_irq.pending || load(g_db.pending)) return kIdleWoken;
    std::uint64_t now = now_ns();
    if (poll_ns && !poll_doorbell_until(seen, now + poll_ns < wake_ns ? now + poll_ns : wake_ns)) {
        store(g_db.state, kDbRunning);
        return kIdleWoken;
    }
    IdleEnd end = kIdleTimedOut;
    now = now_ns();
    if (now < wake_ns) {
        store(g_db.state, kDbSleeping);
        // As in idle_wait_locked: a ring or tick after `seen` makes the
        // wait return at once; the timeout is the early wake-up.
        if (load(g_db.seq) != seen || g_irq.pending) {
            end = kIdleWoken;
        } else {
            const std::uint64_t left = wake_ns - now;
            timespec ts{time_t(left / 1000000000u), long(left % 1000000000u)};
            const long r = syscall(SYS_futex, g_db.seq, g_db.shared ? FUTEX_WAIT : (FUTEX_WAIT | FUTEX_PRIVATE_FLAG),
                                   seen, &ts, nullptr, 0);
            if (r != 0 && errno == ETIMEDOUT) {
                const std::uint64_t woke = now_ns();
                *woke_late = woke > wake_ns ? woke - wake_ns : 0;
            }
            if (load(g_db.seq) != seen || g_irq.pending || now_ns() < wake_ns) end = kIdleWoken;
        }
    }
    store(g_db.state, kDbRunning);
    return end;
}

IdleEnd idle_poll_until_locked(std::uint64_t due_ns) {
    const std::uint32_t seen = load(g_db.seq);
    if (g_irq.pending || load(g_db.pending)) return kIdleWoken;
    const bool due = poll_doorbell_until(seen, due_ns);
    store(g_db.state, kDbRunning);
    return due ? kIdleDue : kIdleWoken;
}

CHM_HOT int idle_wait_fds_locked(pollfd* fds, unsigned long nfds, std::uint64_t until_ns) {
    const std::uint32_t seen = load(g_db.seq);
    sigset_t block, during;
    sigemptyset(&block);
    sigaddset(&block, timer_signal());
    pthread_sigmask(SIG_BLOCK, &block, &during);
    sigdelset(&during, timer_signal());
    store(g_db.state, kDbSleepingFds);
    int ready = 0;
    // A tick or ring from here on is either seen by this test or kept
    // pending (signal blocked) until ppoll unblocks it atomically.
    if (!g_irq.pending && !load(g_db.pending) && load(g_db.seq) == seen) {
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
    store(g_db.state, kDbRunning);
    pthread_sigmask(SIG_UNBLOCK, &block, nullptr);
    return ready;
}

void idle_wake() { doorbell_ring(g_db, 0, interrupt_own_kernel, nullptr); }

}  // namespace chm::port
