// The monitor thread of an attached process: beats its slot's heartbeat and
// watches every other live slot, so a peer killed with SIGKILL is found
// within milliseconds and recovered (recovery.cpp).
//
// Watching: one pidfd per live peer (pidfd_open, Linux 5.3+) in one poll();
// a pidfd turns readable the moment its process exits. Where pidfd_open is
// missing (qemu-user, old kernels) the thread instead checks each peer's
// /proc entry (existence, not a zombie, same start time) every 10 ms.
// The thread blocks every signal, the kernel's timer signal included: the
// kernel guarantees that only its own thread ever takes that signal.
#include <cerrno>
#include <csignal>
#include <cstring>
#include <ctime>

#include <poll.h>
#include <pthread.h>
#include <sys/eventfd.h>
#include <sys/syscall.h>
#include <unistd.h>

#include "ipc/backplane/backplane.hpp"
#include "port.hpp"

namespace chm::bp {

namespace {

constexpr int kPeriodMs = 10;
// One recovery attempt from this thread waits at most this long for a
// lock a live process holds; the next scan tries again (any survivor
// may), so the heartbeat, the other slots and monitor_stop are never held
// up longer.
constexpr std::uint64_t kAttemptNs = 100'000'000;
// monitor_stop(before_fork): how long it waits for the joined thread to be
// gone from the OS (natively microseconds after the join).
constexpr std::uint64_t kThreadGoneNs = 1'000'000'000;

struct Watch {
    std::uint32_t status = 0;  // the status this watch was opened for
    int pidfd = -1;
    bool gone = false;         // its process is already known dead
    std::uint32_t dead_since = 0;  // JOINING: first seen dead (ms), 0 = not
    std::uint32_t pid_seen = 0;    // JOINING: the pid word then
};

struct Monitor {
    Attachment* att = nullptr;
    pthread_t thread{};
    int wake_fd = -1;
    bool running = false;
    std::atomic<bool> stop{false};  // monitor_stop: ends the thread's lock waits too (WaitBound)
    std::atomic<int> os_tid{0};     // the thread's kernel id, set by the thread itself
    bool no_pidfd = false;
    Watch w[kMaxSlots];
};
Monitor g_mon;

int open_pidfd(int pid) {
#ifdef SYS_pidfd_open
    return int(::syscall(SYS_pidfd_open, pid, 0));
#else
    (void)pid;
    errno = ENOSYS;
    return -1;
#endif
}

void forget(Watch& w) {
    if (w.pidfd >= 0) ::close(w.pidfd);
    w = Watch{};
}

// (Re)arm the watch of a slot that is live with status `st`.
void arm(Monitor& m, std::uint32_t s, std::uint32_t st) {
    Watch& w = m.w[s];
    if (w.status == st && (w.pidfd >= 0 || m.no_pidfd || w.gone)) return;
    forget(w);
    w.status = st;
    const RtpuEntry* e = m.att->rtpu(s);
    const int pid = int(e->pid.load(std::memory_order_acquire));
    if (m.no_pidfd) return;
    const int fd = open_pidfd(pid);
    if (fd < 0) {
        if (errno == ENOSYS || errno == EPERM) m.no_pidfd = true;
        else w.gone = true;  // ESRCH: already gone
        return;
    }
    // The pidfd names whoever has `pid` now; it is the slot's process only
    // if the start time still matches (else the pid was reused).
    if (!proc_alive(pid, e->pid_start.load())) {
        ::close(fd);
        w.gone = true;
        return;
    }
    w.pidfd = fd;
}

void attempt(const View& v, std::uint32_t s, std::uint32_t gen) {
    WaitBound bound(kAttemptNs);
    recover_slot(v, s, gen);
}

void scan(Monitor& m) {
    const View& v = *m.att;
    const std::uint32_t now = mono_ms();
    v.rtpu(m.att->slot)->heartbeat_ms.store(now, std::memory_order_relaxed);
    for (std::uint32_t s = 0; s < v.slots(); ++s) {
        if (m.stop.load(std::memory_order_relaxed)) return;
        if (s == m.att->slot) continue;
        const std::uint32_t st = v.rtpu(s)->status.load(std::memory_order_acquire);
        const SlotState state = status_state(st);
        if (state == SlotState::Recovering) {
            forget(m.w[s]);
            if (slot_holder_dead(v, s, st)) attempt(v, s, status_gen(st));  // takes over
            continue;
        }
        if (state != SlotState::Joining && state != SlotState::Running && state != SlotState::Leaving) {
            forget(m.w[s]);
            continue;
        }
        // A JOINING slot may not name its process yet (attach.cpp): it is
        // judged on its words, which must stay the same for kConfirmMs.
        if (state == SlotState::Joining) {
            Watch& w = m.w[s];
            const std::uint32_t pid = v.rtpu(s)->pid.load(std::memory_order_acquire);
            if (w.pidfd >= 0 || w.gone) forget(w);
            const bool alive = pid_named(pid) && !slot_holder_dead(v, s, st);
            if (alive || w.status != st || w.pid_seen != pid || !w.dead_since) {
                w.status = st;
                w.pid_seen = pid;
                w.dead_since = alive ? 0 : (now ? now : 1);
                continue;
            }
            const std::uint32_t confirm = pid_named(pid) ? kConfirmMs : kUnnamedConfirmMs;
            if (now - w.dead_since < confirm || !joining_abandon(v, s, st, pid)) continue;
            attempt(v, s, status_gen(st));
            forget(w);
            continue;
        }
        arm(m, s, st);
        Watch& w = m.w[s];
        bool dead = w.gone;
        if (!dead && w.pidfd < 0) dead = slot_holder_dead(v, s, st);  // the /proc fallback
        if (!dead) continue;
        attempt(v, s, status_gen(st));
        forget(w);
    }
}

// Does this process still have OS thread `tid`? (tgkill with signal 0:
// ESRCH once the thread has finished exiting.)
bool thread_exists(int tid) {
    return ::syscall(SYS_tgkill, ::getpid(), tid, 0) == 0 || errno != ESRCH;
}

void wait_thread_gone(int tid) {
    if (tid <= 0) return;
    const std::uint64_t end = port::now_ns() + kThreadGoneNs;
    while (thread_exists(tid) && port::now_ns() < end) {
        const timespec nap{0, 100'000};
        ::nanosleep(&nap, nullptr);
    }
}

void* run(void*) {
    Monitor& m = g_mon;
    m.os_tid.store(int(::syscall(SYS_gettid)), std::memory_order_relaxed);
    pollfd fds[kMaxSlots + 1];
    std::uint32_t who[kMaxSlots + 1];
    const WaitBound stoppable(UINT64_MAX, &m.stop);
    while (!m.stop.load(std::memory_order_relaxed)) {
        scan(m);
        nfds_t n = 0;
        fds[n++] = pollfd{m.wake_fd, POLLIN, 0};
        for (std::uint32_t s = 0; s < kMaxSlots; ++s) {
            if (m.w[s].pidfd < 0) continue;
            who[n] = s;
            fds[n++] = pollfd{m.w[s].pidfd, POLLIN, 0};
        }
        const int r = ::poll(fds, n, kPeriodMs);
        if (r > 0 && (fds[0].revents & POLLIN)) break;  // monitor_stop
        if (r > 0) {
            for (nfds_t i = 1; i < n; ++i)
                if (fds[i].revents) m.w[who[i]].gone = true;  // exited: the next scan recovers it
        }
    }
    return nullptr;
}

}  // namespace

int monitor_start(Attachment* a) {
    Monitor& m = g_mon;
    if (m.running) return -EBUSY;
    for (auto& w : m.w) w = Watch{};
    m.stop.store(false);
    m.att = a;
    m.no_pidfd = false;
    m.wake_fd = ::eventfd(0, EFD_CLOEXEC);
    if (m.wake_fd < 0) return -errno;
    // Created with every signal blocked, so the thread never takes one.
    sigset_t all, old;
    sigfillset(&all);
    ::pthread_sigmask(SIG_SETMASK, &all, &old);
    pthread_attr_t attr;
    ::pthread_attr_init(&attr);
    ::pthread_attr_setstacksize(&attr, 64 * 1024);
    const int r = ::pthread_create(&m.thread, &attr, run, nullptr);
    ::pthread_attr_destroy(&attr);
    ::pthread_sigmask(SIG_SETMASK, &old, nullptr);
    if (r != 0) {
        ::close(m.wake_fd);
        m.wake_fd = -1;
        return -r;
    }
    m.running = true;
    return 0;
}

void monitor_stop(bool before_fork) {
    Monitor& m = g_mon;
    if (!m.running) return;
    // The flag ends a lock wait of the thread within one polling interval
    // (lock_acquire), the eventfd its poll; so the join below waits at most
    // for one step of a scan that does not wait (docs/backplane.md, "Every
    // wait and its bound").
    m.stop.store(true);
    const std::uint64_t one = 1;
    (void)!::write(m.wake_fd, &one, sizeof one);
    ::pthread_join(m.thread, nullptr);
    if (before_fork) wait_thread_gone(m.os_tid.load(std::memory_order_relaxed));
    m.os_tid.store(0, std::memory_order_relaxed);
    ::close(m.wake_fd);
    m.wake_fd = -1;
    for (auto& w : m.w) forget(w);
    m.running = false;
    m.att = nullptr;
}

void monitor_forget_after_fork() {
    Monitor& m = g_mon;
    if (!m.running) return;
    if (m.wake_fd >= 0) ::close(m.wake_fd);
    m.wake_fd = -1;
    for (auto& w : m.w) forget(w);
    m.running = false;
    m.att = nullptr;
}

}  // namespace chm::bp
