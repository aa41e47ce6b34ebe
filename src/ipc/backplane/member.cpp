// The one place Chimera signals another process of a backplane (wake-up
// rings, chimera stop). The RTPU table is file contents anyone with write
// access can change, so a pid or thread id read from it is only a claim:
// before the first signal the kernel's view of that process is checked
// (/proc: alive with the start time the table records, running as a user
// the backplane trusts, this very backplane file mapped; a thread id a
// thread of it, the timer signal caught). A claim that fails is reported
// (slot, field, value) and never signalled.
//
// Thread signals (rings) are on the hot wake path: the verdict is cached
// per slot in process memory, keyed by the slot's status word (generation
// and state), pid and thread id as the table holds them, so a wake whose
// key matches costs three compares; any change of the key is a fresh
// check. Process signals (chimera stop) are rare and checked afresh each
// time, through a pidfd opened before the check so the signal reaches the
// process that was checked even if its pid is reused meanwhile.
#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include <fcntl.h>
#include <poll.h>
#include <sys/stat.h>
#include <sys/syscall.h>
#include <sys/sysmacros.h>
#include <unistd.h>

#include "ipc/backplane/backplane.hpp"
#include "port.hpp"

namespace chm::bp {

namespace {

constexpr auto R = std::memory_order_relaxed;

// One slot's cached verdict. A seqlock: `seq` odd while a writer changes
// the rest; a reader that sees it move treats the entry as a miss. Writers
// never wait (CAS or give up), so a signal handler may run the slow path.
struct Verdict {
    std::atomic<std::uint32_t> seq{0};
    std::atomic<std::uint32_t> status{0}, pid{0}, tid{0}, ok{0};
};
Verdict g_cache[kMaxSlots];

// /proc/<pid>/<rest> relative to a /proc descriptor (qemu-user fakes only
// paths that name its own process, proc.cpp). No stdio: may run in a
// signal handler.
int open_proc(int pid, const char* rest) {
    static std::atomic<int> s_proc{-1};
    int dir = s_proc.load(std::memory_order_acquire);
    if (dir < 0) {
        int fd = ::open("/proc", O_RDONLY | O_DIRECTORY | O_CLOEXEC);
        int expected = -1;
        if (fd >= 0 && !s_proc.compare_exchange_strong(expected, fd)) {
            ::close(fd);
            fd = expected;
        }
        dir = fd;
    }
    char path[64];
    char digits[16];
    int d = 0;
    for (unsigned v = unsigned(pid); v; v /= 10) digits[d++] = char('0' + v % 10);
    char* p = path;
    while (d) *p++ = digits[--d];
    *p++ = '/';
    const std::size_t n = std::strlen(rest);
    if (n + 1 > sizeof path - std::size_t(p - path)) return -1;
    std::memcpy(p, rest, n + 1);
    return ::openat(dir, path, O_RDONLY | O_CLOEXEC);
}

// Read /proc/<pid>/status into buf (NUL-terminated); false when gone.
bool read_status(int pid, char* buf, std::size_t n) {
    const int fd = open_proc(pid, "status");
    if (fd < 0) return false;
    const ssize_t got = ::read(fd, buf, n - 1);
    ::close(fd);
    if (got <= 0) return false;
    buf[got] = 0;
    return true;
}

// The numbers after "Key:\t" in a status text (up to `max`); their count.
int status_numbers(const char* text, const char* key, unsigned long long* out, int max, int base = 10) {
    const char* s = std::strstr(text, key);
    if (!s) return 0;
    s += std::strlen(key);
    int k = 0;
    while (k < max) {
        while (*s == ' ' || *s == '\t') ++s;
        char* end = nullptr;
        const unsigned long long v = std::strtoull(s, &end, base);
        if (end == s) break;
        out[k++] = v;
        s = end;
    }
    return k;
}

// Does the process run as a user this backplane trusts: one of its uids
// ours (or root's when we are root), or, for a backplane made for a group,
// that group among its groups?
bool trusted_user(const char* st, const struct stat& file, const Header* h) {
    unsigned long long ids[4];
    const int nu = status_numbers(st, "\nUid:", ids, 4);
    for (int i = 0; i < nu; ++i)
        if (ids[i] == ::geteuid()) return true;
    if (h->ext[kExtGroupFlag] != kGroupMarker) return false;
    const unsigned long long gid = file.st_gid;
    unsigned long long g[64];
    int ng = status_numbers(st, "\nGid:", g, 4);
    for (int i = 0; i < ng; ++i)
        if (g[i] == gid) return true;
    ng = status_numbers(st, "\nGroups:", g, 64);
    for (int i = 0; i < ng; ++i)
        if (g[i] == gid) return true;
    return false;
}

// Does /proc/<pid>/maps list a mapping of the file (device, inode)?
bool maps_file(int pid, const struct stat& file) {
    const int fd = open_proc(pid, "maps");
    if (fd < 0) return false;
    char buf[4096];
    std::size_t have = 0;
    bool found = false;
    for (;;) {
        const ssize_t got = ::read(fd, buf + have, sizeof buf - 1 - have);
        if (got <= 0) break;
        have += std::size_t(got);
        buf[have] = 0;
        char* line = buf;
        for (char* nl; !found && (nl = std::strchr(line, '\n')); line = nl + 1) {
            *nl = 0;
            // start-end perms offset MAJ:MIN inode path
            unsigned maj = 0, min = 0;
            unsigned long long ino = 0;
            if (std::sscanf(line, "%*s %*s %*s %x:%x %llu", &maj, &min, &ino) == 3 &&
                ino == file.st_ino && maj == major(file.st_dev) && min == minor(file.st_dev))
                found = true;
        }
        if (found) break;
        have = std::size_t(buf + have - line);
        if (have == sizeof buf - 1) have = 0;  // a line longer than the buffer: skip it
        std::memmove(buf, line, have);
    }
    ::close(fd);
    return found;
}

// The kernel's answer to "is `pid` (and `tid`, when non-zero) the member
// in slot `slot`?" 0, or -EPERM with `why` naming slot, field and value.
int verify(const View& v, int fd, std::uint32_t slot, int pid, int tid, char* why, std::size_t n) {
    const RtpuEntry* e = v.rtpu(slot);
    auto refuse = [&](const char* field, int value, const char* what) {
        std::snprintf(why, n, "RTPU table slot %u: %s %d %s: not signalled", slot, field, value, what);
        return -EPERM;
    };
    if (pid <= 0) return refuse("pid", pid, "names no process");
    if (pid == ::getpid()) {
        // Ourselves: only our own slot, only our kernel thread.
        const Attachment* a = current();
        if (!a || a->slot != slot) return refuse("pid", pid, "is this process, which holds another slot");
        if (tid && tid != port::kernel_tid()) return refuse("tid", tid, "is not this process's kernel thread");
        return 0;
    }
    const std::uint64_t start = proc_start_time(pid);
    if (start == 0) return refuse("pid", pid, "names no live process");
    if (start != e->pid_start.load()) return refuse("pid", pid, "names a process other than the one that joined (start time differs)");
    struct stat file{};
    if (::fstat(fd, &file) != 0) return refuse("pid", pid, "cannot be checked (the backplane file cannot be fstat'ed)");
    char st[4096];
    if (!read_status(pid, st, sizeof st)) return refuse("pid", pid, "names no live process");
    if (!trusted_user(st, file, v.hdr())) return refuse("pid", pid, "runs as a user this backplane does not trust");
    if (!maps_file(pid, file)) return refuse("pid", pid, "names a process that does not map this backplane");
    if (tid) {
        char task[32];
        std::snprintf(task, sizeof task, "task/%d/stat", tid);
        const int t = open_proc(pid, task);
        if (t < 0) return refuse("tid", tid, "is not a thread of the slot's process");
        ::close(t);
        unsigned long long caught = 0;
        const int sig = port::timer_signal();
        if (status_numbers(st, "\nSigCgt:", &caught, 1, 16) != 1 || !(caught >> (sig - 1) & 1))
            return refuse("tid", tid, "belongs to a process that does not catch Chimera's wake signal");
    }
    return 0;
}

// Report a refusal: the thread's last-error text and one line on stderr
// (the RTPU's log). Async-signal-safe enough: no allocation.
void report(const char* why) {
    const Attachment* a = current();
    set_error("backplane %s: %s", a ? a->path : "?", why);
    char line[512];
    const int len = std::snprintf(line, sizeof line, "chimera: backplane %s: %s\n", a ? a->path : "?", why);
    if (len > 0) (void)!::write(2, line, std::size_t(len) < sizeof line ? std::size_t(len) : sizeof line - 1);
}

int pidfd_open(int pid) {
#ifdef SYS_pidfd_open
    return int(::syscall(SYS_pidfd_open, pid, 0));
#else
    (void)pid;
    errno = ENOSYS;
    return -1;
#endif
}

int pidfd_signal(int pidfd, int sig) {
#ifdef SYS_pidfd_send_signal
    return int(::syscall(SYS_pidfd_send_signal, pidfd, sig, nullptr, 0));
#else
    (void)pidfd, (void)sig;
    errno = ENOSYS;
    return -1;
#endif
}

// A refused member whose pid names a process that exited, is a zombie or
// is exiting died before its slot was recovered: a death, not a forged
// entry. Nothing
// is signalled either way; the caller learns the member is gone (-ESRCH,
// as for a member that left), not a refusal (-EPERM, which express mail
// returned to the user for a peer killed a moment before, where the API
// promises -EHOSTDOWN once the slot is recovered), and nothing is written
// to stderr.
// Exited, a zombie, or exiting: the kernel sets PF_EXITING (0x4 in the
// flags, field 9 of /proc/PID/stat) as the exit begins, before the process
// unmaps its memory and its threads go, which the checks above then miss.
bool exiting(int pid) {
    const int fd = open_proc(pid, "stat");
    if (fd < 0) return true;
    char buf[1024];
    const ssize_t n = ::read(fd, buf, sizeof buf - 1);
    ::close(fd);
    if (n <= 0) return true;
    buf[n] = 0;
    const char* s = std::strrchr(buf, ')');
    if (!s || s[1] != ' ') return false;
    s += 2;  // field 3: state
    if (*s == 'Z' || *s == 'X' || *s == 'x') return true;
    for (int field = 3; field < 9; ++field) {
        s = std::strchr(s, ' ');
        if (!s) return false;
        ++s;
    }
    unsigned long flags = 0;
    while (*s >= '0' && *s <= '9') flags = flags * 10 + unsigned(*s++ - '0');
    return flags & 0x4;
}

bool gone(std::uint32_t slot, std::uint32_t pid) {
    if (!exiting(int(pid))) return false;
    set_error("backplane %s: RTPU table slot %u: pid %u has exited or is exiting: not signalled",
              current() ? current()->path : "?", slot, pid);
    return true;
}

int signal_thread(const View& v, int fd, std::uint32_t slot, int sig) {
    const RtpuEntry* e = v.rtpu(slot);
    const std::uint32_t status = e->status.load(std::memory_order_acquire);
    const std::uint32_t pid = e->pid.load(std::memory_order_acquire);
    const std::uint32_t tid = e->tid.load(std::memory_order_acquire);
    if (tid == 0) return -ESRCH;
    Verdict& c = g_cache[slot];
    const std::uint32_t s1 = c.seq.load(std::memory_order_acquire);
    int ok = -1;  // -1: miss
    if (!(s1 & 1) && c.status.load(R) == status && c.pid.load(R) == pid && c.tid.load(R) == tid) {
        const std::uint32_t cached = c.ok.load(R);
        std::atomic_thread_fence(std::memory_order_acquire);
        if (c.seq.load(R) == s1) ok = int(cached);
    }
    if (ok < 0) {
        char why[256];
        const int r = verify(v, fd, slot, int(pid), int(tid), why, sizeof why);
        ok = r == 0;
        std::uint32_t even = s1 & ~1u;
        if (c.seq.compare_exchange_strong(even, even + 1, std::memory_order_acquire)) {
            c.status.store(status, R);
            c.pid.store(pid, R);
            c.tid.store(tid, R);
            c.ok.store(std::uint32_t(ok), R);
            c.seq.store(even + 2, std::memory_order_release);
        }
        if (!ok) {
            if (gone(slot, pid)) return -ESRCH;
            report(why);  // once per key: later wakes hit the cached refusal
            return -EPERM;
        }
    }
    if (!ok) {
        if (gone(slot, pid)) return -ESRCH;
        set_error("backplane %s: RTPU table slot %u: pid %u / tid %u refused before: not signalled",
                  current() ? current()->path : "?", slot, pid, tid);
        return -EPERM;
    }
    return ::syscall(SYS_tgkill, int(pid), int(tid), sig) == 0 ? 0 : -errno;
}

int signal_process(const View& v, int fd, std::uint32_t slot, std::uint32_t status, int sig) {
    const RtpuEntry* e = v.rtpu(slot);
    const int pid = int(e->pid.load(std::memory_order_acquire));
    if (e->status.load(std::memory_order_acquire) != status) return -ESRCH;  // left: nothing to stop
    if (pid == ::getpid()) {
        char why[128];
        std::snprintf(why, sizeof why, "RTPU table slot %u: pid %d is this process: not signalled", slot, pid);
        report(why);
        return -EPERM;
    }
    // Opened first: the checks below then describe the process it names.
    const int pidfd = pid > 0 ? pidfd_open(pid) : -1;
    if (pid > 0 && pidfd < 0 && errno == ESRCH) return -ESRCH;
    char why[256];
    int r = verify(v, fd, slot, pid, 0, why, sizeof why);
    if (r == 0 && pidfd >= 0) {
        pollfd p{pidfd, POLLIN, 0};
        if (::poll(&p, 1, 0) == 1) r = -ESRCH;  // exited since the open
    }
    if (r == -EPERM) report(why);
    if (r == 0) {
        if (pidfd >= 0) r = pidfd_signal(pidfd, sig) == 0 ? 0 : -errno;
        // No pidfd (qemu-user, old kernels): the start time, checked once
        // more right before the signal, is what guards against reuse.
        if (pidfd < 0 || r == -ENOSYS) r = proc_start_time(pid) == e->pid_start.load() && ::kill(pid, sig) == 0 ? 0 : -ESRCH;
    }
    if (pidfd >= 0) ::close(pidfd);
    return r;
}

}  // namespace

int signal_member(std::uint32_t slot, MemberTarget target, int sig, std::uint32_t status) {
    const Attachment* a = current();
    if (!a) return -ENOTCONN;
    if (slot >= a->slots()) return -EINVAL;
    return target == MemberTarget::KernelThread ? signal_thread(*a, a->fd, slot, sig)
                                                : signal_process(*a, a->fd, slot, status, sig);
}

int open_member_file(std::uint32_t slot, int remote_fd, int* out) {
    *out = -1;
    const Attachment* a = current();
    if (!a) return -ENOTCONN;
    if (slot >= a->slots() || remote_fd < 0) return -EINVAL;
    const RtpuEntry* e = a->rtpu(slot);
    const std::uint32_t status = e->status.load(std::memory_order_acquire);
    const int pid = int(e->pid.load(std::memory_order_acquire));
    char why[256];
    // A member in this very process (tests run the host server in a
    // thread) needs no check: the descriptor is ours.
    if (pid != ::getpid()) {
        if (int r = verify(*a, a->fd, slot, pid, 0, why, sizeof why)) {
            report(why);
            return r;
        }
    }
    char rest[32];
    std::snprintf(rest, sizeof rest, "fd/%d", remote_fd);
    const int fd = open_proc(pid, rest);
    if (fd < 0) return -errno;
    // Still the member checked above (its pid not reused meanwhile).
    if (proc_start_time(pid) != e->pid_start.load() || e->status.load(std::memory_order_acquire) != status) {
        ::close(fd);
        return -ESRCH;
    }
    *out = fd;
    return 0;
}

void member_forget() {
    for (Verdict& c : g_cache) {
        c.seq.store(0, R);
        c.status.store(0, R);
        c.pid.store(0, R);
        c.tid.store(0, R);
        c.ok.store(0, R);
    }
}

}  // namespace chm::bp
