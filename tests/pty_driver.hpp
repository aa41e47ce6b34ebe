// A child process on a pseudo-terminal, driven by a test: it types at the
// master side and reads what the terminal shows. Every wait is bounded
// (kWaitMs, generous: under qemu everything is slower); the child is
// killed and reaped whatever happens.
#pragma once

#include <gtest/gtest.h>

#include <fcntl.h>
#include <poll.h>
#include <pty.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <initializer_list>
#include <cstdlib>
#include <string>

namespace chm::test {

inline constexpr int kWaitMs = 20000;

struct Pty {
    int wait_ms = kWaitMs;
    pid_t pid = -1;
    int master = -1;
    std::string seen;      // everything the terminal showed
    std::size_t mark = 0;  // where the next read_until starts looking

    ~Pty() {
        if (pid > 0) {
            kill(pid, SIGKILL);
            waitpid(pid, nullptr, 0);
        }
        if (master >= 0) close(master);
    }

    // Fork a child on a new 80x24 terminal running body(); false if forkpty failed.
    template <typename F>
    bool start(F body) {
        winsize ws{};
        ws.ws_row = 24;
        ws.ws_col = 80;
        pid = forkpty(&master, nullptr, nullptr, &ws);
        if (pid == 0) {
            setenv("TERM", "xterm", 1);
            _exit(body());
        }
        return pid > 0;
    }

    // Read what the terminal shows until `want` appears after the mark
    // (then the mark moves past it) or kWaitMs passes.
    bool read_until(const std::string& want) {
        const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(wait_ms);
        for (;;) {
            const std::size_t at = seen.find(want, mark);
            if (at != std::string::npos) {
                mark = at + want.size();
                return true;
            }
            const auto left =
                std::chrono::duration_cast<std::chrono::milliseconds>(end - std::chrono::steady_clock::now()).count();
            if (left <= 0) return false;
            pollfd p{master, POLLIN, 0};
            if (poll(&p, 1, static_cast<int>(left)) <= 0) continue;
            char buf[4096];
            const ssize_t n = read(master, buf, sizeof buf);
            if (n <= 0) return seen.find(want, mark) != std::string::npos;  // the child is gone
            seen.append(buf, static_cast<std::size_t>(n));
        }
    }

    // Read until every one of `wants` appears somewhere after `from` (in
    // any order: two sources, such as a task's output and the console's
    // own notice, may reach the terminal either way round), or the wait
    // ends; then the mark moves past all of them.
    bool read_all_of(std::initializer_list<std::string> wants, std::size_t from) {
        const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(wait_ms);
        for (;;) {
            std::size_t last = from;
            bool all = true;
            for (const std::string& w : wants) {
                const std::size_t at = seen.find(w, from);
                if (at == std::string::npos) all = false;
                else last = std::max(last, at + w.size());
            }
            if (all) {
                mark = std::max(mark, last);
                return true;
            }
            if (std::chrono::steady_clock::now() >= end) return false;
            pump(50);
        }
    }

    // Read what the terminal shows for up to `ms` milliseconds.
    void pump(int ms) {
        const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(ms);
        for (;;) {
            const auto left =
                std::chrono::duration_cast<std::chrono::milliseconds>(end - std::chrono::steady_clock::now()).count();
            if (left <= 0) return;
            pollfd p{master, POLLIN, 0};
            if (poll(&p, 1, static_cast<int>(left)) <= 0) continue;
            char buf[65536];
            const ssize_t n = read(master, buf, sizeof buf);
            if (n <= 0) return;
            seen.append(buf, static_cast<std::size_t>(n));
        }
    }

    void type(const std::string& keys) { ASSERT_EQ(write(master, keys.data(), keys.size()), ssize_t(keys.size())); }

    // The child's exit status, reaped within kWaitMs (-1: it did not end).
    int wait_exit() {
        const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(wait_ms);
        while (std::chrono::steady_clock::now() < end) {
            int st = 0;
            if (waitpid(pid, &st, WNOHANG) == pid) {
                pid = -1;
                return WIFEXITED(st) ? WEXITSTATUS(st) : 100 + WTERMSIG(st);
            }
            char buf[4096];
            pollfd p{master, POLLIN, 0};
            if (poll(&p, 1, 20) <= 0) continue;
            const ssize_t n = read(master, buf, sizeof buf);
            if (n > 0) seen.append(buf, static_cast<std::size_t>(n));
        }
        return -1;
    }
};

}  // namespace chm::test
