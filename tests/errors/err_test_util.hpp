// Helpers of the errors suite: run a scenario in a forked child (a
// fail-stop or a stray fault cannot take the test runner down) and capture
// what it writes to stderr; bounded waits everywhere.
#pragma once

#include <gtest/gtest.h>

#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <functional>
#include <poll.h>
#include <string>
#include <sys/wait.h>
#include <unistd.h>

#include "chimera/chimera.h"
#include "chimera/err.h"

namespace chm::test {

inline constexpr uint64_t kMs = 1000000;

struct ChildResult {
    bool exited = false;    // exited normally
    int status = -1;        // exit status, or the signal that killed it
    bool timed_out = false;
    std::string err;        // everything written to stderr
};

// Run `body` in a child process whose stderr is captured; the child exits
// with body's return value. Killed after `limit_s` seconds.
inline ChildResult run_child(const std::function<int()>& body, int limit_s = 60) {
    ChildResult r;
    int p[2];
    if (pipe(p) != 0) return r;
    std::fflush(nullptr);
    const pid_t pid = fork();
    if (pid == 0) {
        close(p[0]);
        dup2(p[1], 2);
        close(p[1]);
        const int rc = body();
        std::fflush(nullptr);
        _exit(rc);
    }
    close(p[1]);
    const long deadline = long(std::time(nullptr)) + limit_s;
    char buf[4096];
    for (;;) {
        pollfd pf{p[0], POLLIN, 0};
        const int n = poll(&pf, 1, 200);
        if (n > 0) {
            const ssize_t k = read(p[0], buf, sizeof buf);
            if (k > 0) {
                r.err.append(buf, size_t(k));
                continue;
            }
            break;  // EOF: the child is gone (or closed stderr)
        }
        if (long(std::time(nullptr)) > deadline) {
            kill(pid, SIGKILL);
            r.timed_out = true;
            break;
        }
    }
    close(p[0]);
    int st = 0;
    while (waitpid(pid, &st, 0) < 0 && errno == EINTR) {
    }
    if (WIFEXITED(st)) {
        r.exited = true;
        r.status = WEXITSTATUS(st);
    } else if (WIFSIGNALED(st)) {
        r.status = WTERMSIG(st);
    }
    return r;
}

inline int count_lines(const std::string& s, const std::string& needle) {
    int n = 0;
    for (size_t at = s.find(needle); at != std::string::npos; at = s.find(needle, at + 1)) ++n;
    return n;
}

inline chm_tid_t spawn_task(void (*fn)(void*), void* arg, const char* name, int prio = 0,
                            uint64_t period = 0, chm_deadline_handler_t on_deadline = nullptr,
                            size_t stack = 0) {
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = name;
    a.priority = prio;
    a.period_ns = period;
    a.on_deadline = on_deadline;
    a.stack_size = stack;
    chm_tid_t id = CHM_TID_NONE;
    if (chm_task_spawn(&id, fn, arg, &a) != 0) return CHM_TID_NONE;
    return id;
}

}  // namespace chm::test
