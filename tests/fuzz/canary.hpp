// A canary for the harnesses (issue 21): a live `sleep` process whose pid
// (and thread id: it is single-threaded, so the same number) the harness
// writes wherever a backplane names a process or thread. Signals go only
// to processes the kernel confirms are members (bp::signal_member), so
// whatever an input does, the canary must still be alive afterwards;
// alive_or_abort() stops the run with the input that killed it.
#pragma once

#include <cstdint>
#include <cstdio>
#include <cstdlib>

#include <csignal>
#include <sys/wait.h>
#include <unistd.h>

#include "ipc/backplane/backplane.hpp"

namespace chm::fuzz {

struct Canary {
    pid_t pid = -1;
    std::uint64_t start = 0;  // /proc start time, so the slot looks alive
};

inline Canary start_canary() {
    Canary c;
    c.pid = ::fork();
    if (c.pid == 0) {
        ::execl("/bin/sleep", "sleep", "100000", static_cast<char*>(nullptr));
        ::_exit(127);
    }
    if (c.pid < 0) {
        std::perror("canary");
        std::exit(2);
    }
    // Wait for the exec: before it the child is a copy of this process.
    for (int i = 0; i < 2000; ++i) {
        char exe[64] = {}, path[32];
        std::snprintf(path, sizeof path, "/proc/%d/exe", int(c.pid));
        if (::readlink(path, exe, sizeof exe - 1) > 0 && std::string(exe).find("sleep") != std::string::npos) break;
        ::usleep(1000);
    }
    c.start = bp::proc_start_time(c.pid);
    static pid_t s_pid = c.pid;
    std::atexit([] { ::kill(s_pid, SIGKILL); ::waitpid(s_pid, nullptr, 0); });
    return c;
}

inline void alive_or_abort(const Canary& c, const char* after) {
    int st = 0;
    if (::waitpid(c.pid, &st, WNOHANG) != 0) {
        std::fprintf(stderr, "canary (pid %d) died after %s: %s %d\n", int(c.pid), after,
                     WIFSIGNALED(st) ? "signal" : "exit", WIFSIGNALED(st) ? WTERMSIG(st) : WEXITSTATUS(st));
        std::abort();
    }
}

// Name the canary in every slot of a backplane image that is not free:
// pid, kernel thread, recoverer, their start times (so the slot looks
// alive), the doorbell asleep in ppoll (a ring then sends a signal).
inline void plant(char* base, const bp::Layout& l, const Canary& c) {
    for (std::uint32_t s = 0; s < l.geo.rtpu_slots; ++s) {
        auto* e = reinterpret_cast<bp::RtpuEntry*>(base + l.regions[bp::kRegionTable].offset) + s;
        if (bp::status_state(e->status.load()) == bp::SlotState::Free) continue;
        e->pid.store(std::uint32_t(c.pid));
        e->tid.store(std::uint32_t(c.pid));
        e->pid_start.store(c.start);
        e->recoverer.store(bp::recoverer_word(std::uint32_t(c.pid), c.start));
        e->idle.store(3);
    }
}

}  // namespace chm::fuzz
