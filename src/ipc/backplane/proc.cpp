// Facts about processes and time that the backplane's robustness rests on:
// whether a pid is still the process that joined (start time, field 22 of
// /proc/<pid>/stat, so a reused pid is not mistaken for it; a zombie counts
// as dead), a millisecond clock for heartbeats, and how a waiter gives the
// CPU away (to the other tasks of its RTPU when it is a Chimera task).
#include <cerrno>
#include <cstring>
#include <ctime>

#include <fcntl.h>
#include <sys/syscall.h>
#include <unistd.h>

#include "chimera/kernel.h"
#include "chimera/task.h"
#include "ipc/backplane/backplane.hpp"
#include "kernel.hpp"
#include "port.hpp"

namespace chm::bp {

std::uint32_t mono_ms() {
    timespec ts{};
    ::clock_gettime(CLOCK_MONOTONIC, &ts);
    return static_cast<std::uint32_t>(std::uint64_t(ts.tv_sec) * 1000u + std::uint64_t(ts.tv_nsec) / 1000000u);
}

// Relative to a /proc directory descriptor, on purpose: qemu-user fakes
// the contents of a process's own /proc/<pid>/stat (field 22 among them)
// when the path names it, but not a path relative to a directory fd, so
// every process, emulated or not, reads the same start time for a pid.
static int proc_dir() {
    static std::atomic<int> s_fd{-1};
    int fd = s_fd.load(std::memory_order_acquire);
    if (fd >= 0) return fd;
    fd = ::open("/proc", O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    int expected = -1;
    if (fd >= 0 && !s_fd.compare_exchange_strong(expected, fd)) {
        ::close(fd);
        fd = expected;
    }
    return fd;
}

std::uint64_t proc_start_time(int pid) {
    if (pid <= 0) return 0;
    char path[32];
    char buf[1024];
    int n = 0;
    {
        // No stdio: the monitor thread runs this, and stdio may allocate.
        char digits[16];
        int d = 0;
        for (unsigned v = unsigned(pid); v; v /= 10) digits[d++] = char('0' + v % 10);
        char* p = path;
        while (d) *p++ = digits[--d];
        std::memcpy(p, "/stat", sizeof "/stat");
    }
    const int fd = ::openat(proc_dir(), path, O_RDONLY | O_CLOEXEC);
    if (fd < 0) return 0;
    n = int(::read(fd, buf, sizeof buf - 1));
    ::close(fd);
    if (n <= 0) return 0;
    buf[n] = 0;
    // "pid (comm) S ppid ..." -- comm may contain spaces and ')'.
    char* s = std::strrchr(buf, ')');
    if (!s || s[1] != ' ') return 0;
    s += 2;  // field 3: state
    if (*s == 'Z' || *s == 'X' || *s == 'x') return 0;
    for (int field = 3; field < 22; ++field) {
        s = std::strchr(s, ' ');
        if (!s) return 0;
        ++s;
    }
    std::uint64_t v = 0;
    while (*s >= '0' && *s <= '9') v = v * 10 + std::uint64_t(*s++ - '0');
    return v ? v : 1;  // a start of 0 (boot) still means "alive"
}

bool proc_alive(int pid, std::uint64_t start) {
    if (pid <= 0) return false;
    if (pid == ::getpid()) return true;
    const std::uint64_t now = proc_start_time(pid);
    if (now == 0) return false;
    if (start == 0) return true;
    return now == start;
}

std::uint32_t self_recoverer_word() {
    return recoverer_word(std::uint32_t(::getpid()), self_start_time());
}

bool recoverer_alive(std::uint32_t w) {
    const int pid = int(recoverer_pid_of(w));
    if (pid == 0) return false;
    if (pid == ::getpid()) return w == self_recoverer_word();
    const std::uint64_t now = proc_start_time(pid);
    return now != 0 && recoverer_word(std::uint32_t(pid), now) == w;
}

std::uint64_t self_start_time() {
    static std::uint64_t s_start = 0;
    static int s_pid = 0;
    if (s_pid != ::getpid()) {  // recomputed in a forked child
        s_start = proc_start_time(::getpid());
        s_pid = ::getpid();
    }
    return s_start;
}

static bool in_chimera_task() {
    return port::on_kernel_thread() && chm_task_self() != CHM_TID_NONE;
}

void relinquish(std::uint64_t ns) {
    if (in_chimera_task()) {
        chm_task_pause_until(chm_time_now() + ns);
        return;
    }
    timespec ts{static_cast<time_t>(ns / 1000000000u), static_cast<long>(ns % 1000000000u)};
    ::nanosleep(&ts, nullptr);
}

// The thread id is cached: a system call costs ~1 µs on a virtualised
// host, more than the whole uncontended lock.
static thread_local std::uint32_t t_tid = 0;

std::uint32_t task_word() {
    if (port::on_kernel_thread())  // a task: its id's 31-bit form, the layout's word
        if (const kernel::Tcb* t = kernel::g_k.current) return kernel::tid_short(t);
    if (!t_tid) t_tid = 0x80000000u | static_cast<std::uint32_t>(::syscall(SYS_gettid));
    return t_tid;
}

void proc_after_fork_child() { t_tid = 0; }

}  // namespace chm::bp
