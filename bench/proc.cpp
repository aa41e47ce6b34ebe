// Two-process and two-thread plumbing shared by the peers (see proc.hpp).
#include "proc.hpp"

#include <linux/futex.h>
#include <signal.h>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <sys/syscall.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <exception>

namespace chm::bench {

void* map_shared(std::size_t bytes) {
    void* p = mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS, -1, 0);
    check(p != MAP_FAILED, "mmap(MAP_SHARED)");
    return p;
}

void unmap_shared(void* p, std::size_t bytes) { munmap(p, bytes); }

Child::Child(int cpu, const std::function<int()>& body) {
    const pid_t parent = getpid();
    std::fflush(nullptr);  // buffered output must not be written twice
    clear_child_died();
    pid_ = fork();
    check(pid_ >= 0, "fork");
    if (pid_ != 0) return;
    // In the child: never return into the parent's code, never flush its
    // copy of the parent's stdio buffers (_exit).
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != parent) _exit(99);  // the parent died before prctl
    int rc = 1;
    try {
        if (cpu >= 0) Session::pin(cpu);
        rc = body();
    } catch (const std::exception& e) {
        std::fprintf(stderr, "chimera-bench child: %s\n", e.what());
        rc = 2;
    }
    _exit(rc);
}

Child::~Child() {
    if (pid_ <= 0) return;
    kill(pid_, SIGKILL);
    while (waitpid(pid_, nullptr, 0) < 0 && errno == EINTR) {
    }
}

Partner::Partner(int cpu, std::function<void()> body, std::function<void()> stop)
    : stop_(std::move(stop)) {
    t_ = std::thread([cpu, body = std::move(body)] {
        try {
            if (cpu >= 0) Session::pin(cpu);
            body();
        } catch (const std::exception& e) {
            std::fprintf(stderr, "chimera-bench partner thread: %s\n", e.what());
        }
    });
}

Partner::~Partner() {
    stop_();
    t_.join();
}

int futex_wait(std::atomic<std::uint32_t>* w, std::uint32_t expected) {
    static_assert(sizeof(std::atomic<std::uint32_t>) == sizeof(std::uint32_t) &&
                  std::atomic<std::uint32_t>::is_always_lock_free);
    return int(syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(w), FUTEX_WAIT, expected,
                       nullptr, nullptr, 0));
}

void futex_wake(std::atomic<std::uint32_t>* w) {
    syscall(SYS_futex, reinterpret_cast<std::uint32_t*>(w), FUTEX_WAKE, 1, nullptr, nullptr, 0);
}

void for_both_pinnings(Session& s, const std::string& stem, const char* ends,
                       const std::function<void(const std::string&, const Pinning&)>& fn) {
    const int a = s.cpu(0);
    Session::pin(a);
    fn(stem + "_same_core", {a, a, std::string("two ") + ends + ", both pinned " + s.cpu_name(0)});
    if (s.options().cpus.size() < 2) {
        s.skip(stem + "_xcore", "needs 2 CPUs");
        return;
    }
    Session::pin(a);
    fn(stem + "_xcore", {a, s.cpu(1),
                         std::string("two ") + ends + ", pinned " + s.cpu_name(0) + " and " +
                             s.cpu_name(1)});
}

std::string ipc_name(const char* what) {
    return "/chimera-bench-" + std::to_string(getpid()) + "-" + what;
}

}  // namespace chm::bench
