// Multi-process test scaffolding: a private directory per test under
// /dev/shm, forked children (each bounded, killed and reaped in teardown
// even when the test fails), pipes to hand-shake with them, and a runner
// for chimera-bpcheck.
#pragma once

#include <gtest/gtest.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <fstream>
#include <functional>
#include <iterator>
#include <string>
#include <vector>

#include <dirent.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "chimera/bp.h"
#include "ipc/backplane/backplane.hpp"
#include "ipc/backplane/stop_point.hpp"
#include "../private_dir.hpp"

namespace chm::test {

inline std::uint64_t now_ns() {
    timespec ts{};
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return std::uint64_t(ts.tv_sec) * 1000000000ull + std::uint64_t(ts.tv_nsec);
}

inline void sleep_us(unsigned us) {
    timespec ts{time_t(us / 1000000), long(us % 1000000) * 1000};
    nanosleep(&ts, nullptr);
}

// How many times the kill-at-a-named-point tests kill a process at each
// point: 100 in the suite (issue 4), $CHM_KILL_REPEATS when set (the cross
// suites under qemu use fewer, `make stress` thousands).
inline int kill_repeats() {
    const char* e = std::getenv("CHM_KILL_REPEATS");
    const long n = e && *e ? std::strtol(e, nullptr, 10) : 100;
    return n > 0 && n <= 1000000 ? int(n) : 100;
}

// A one-way byte channel between processes.
struct Pipe {
    int fd[2] = {-1, -1};
    Pipe() { EXPECT_EQ(pipe2(fd, O_CLOEXEC), 0); }
    ~Pipe() {
        for (int f : fd)
            if (f >= 0) close(f);
    }
    void put(char c) { (void)!write(fd[1], &c, 1); }
    // The next byte, or -1 after timeout_ms.
    int get(int timeout_ms = 5000) {
        pollfd p{fd[0], POLLIN, 0};
        if (poll(&p, 1, timeout_ms) != 1) return -1;
        char c;
        return read(fd[0], &c, 1) == 1 ? c : -1;
    }
};

inline chm_bp_config_t small_config() {
    chm_bp_config_t c;
    chm_bp_config_init(&c);
    c.rtpu_slots = 8;
    c.ring_records = 8;
    c.ring_record_size = 64;
    c.local_window_size = 64 * 1024;
    c.common_size = 256 * 1024;
    c.registry_capacity = 32;
    return c;
}

// In a forked child: stop at `point` from now on (the parent may have read
// the environment already, so the cached verdict is dropped).
inline void stop_at(const char* point) {
    ::setenv("CHIMERA_STOP_AT", point, 1);
    stop::reload();
}

// Wait (bounded) until process p is stopped (state T in /proc/p/stat),
// without reaping it.
inline bool wait_stopped(pid_t p, int timeout_ms = 10000) {
    const std::uint64_t end = now_ns() + std::uint64_t(timeout_ms) * 1000000u;
    while (now_ns() < end) {
        std::ifstream f("/proc/" + std::to_string(p) + "/stat");
        std::string s((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
        const auto k = s.rfind(')');
        if (k != std::string::npos && k + 2 < s.size() && s[k + 2] == 'T') return true;
        sleep_us(1000);
    }
    return false;
}

// A checker's report (bp::Report::emit) collected as text, a line each.
inline void report_lines(void* ctx, const char* line) { static_cast<std::string*>(ctx)->append(line).append("\n"); }

// check_backplane on this process's attachment: "" when consistent.
inline std::string check_now() {
    std::string out;
    bp::Report r;
    r.emit = report_lines;
    r.ctx = &out;
    bp::check_backplane(*bp::current(), r, nullptr);
    return out;
}

// check_backplane on the file at `path`, mapped read-only without
// attaching (as chimera-bpcheck does): "" when consistent.
inline std::string check_file(const std::string& path) {
    bp::View v;
    int fd = -1;
    char why[320];
    if (bp::map_file(path.c_str(), false, &v, &fd, why, sizeof why, false) != 0)
        return std::string("unreadable: ") + why + "\n";
    std::string out;
    bp::Report r;
    r.emit = report_lines;
    r.ctx = &out;
    bp::check_backplane(v, r, nullptr);
    bp::unmap(&v);
    ::close(fd);
    return out;
}

class IpcTest : public ::testing::Test {
protected:
    void SetUp() override {
        dir_ = make_private_dir("chm-ipc-");
        ASSERT_FALSE(dir_.empty()) << strerror(errno);
        path_ = dir_ + "/test.bp";
    }
    void TearDown() override {
        (void)(void)chm_bp_leave();  // -ENOTCONN when not attached
        for (pid_t p : children_) {
            kill(p, SIGKILL);
            waitpid(p, nullptr, 0);
        }
        children_.clear();
        remove_dir();
    }
    void remove_dir() { remove_private_dir(dir_); }
    std::vector<std::string> dir_entries() { return private_dir_entries(dir_); }
    void create(const chm_bp_config_t& c = small_config()) {
        ASSERT_EQ(chm_bp_create(path_.c_str(), &c), 0) << chm_bp_last_error();
    }
    // Run fn in a child process; its return value is the exit status. A
    // child that outlives `alarm_s` seconds is ended by SIGALRM (a child
    // never outlives a hung test for long): a test whose children may
    // rightly run longer under qemu on a loaded machine passes its own
    // bound, as long as the one it reaps them with.
    pid_t spawn(const std::function<int()>& fn, unsigned alarm_s = 60) {
        fflush(nullptr);
        const pid_t p = fork();
        if (p == 0) {
            alarm(alarm_s);
            _exit(fn());
        }
        EXPECT_GT(p, 0);
        if (p > 0) children_.push_back(p);
        return p;
    }
    // The child's exit status, -SIGNAL if killed, or 1000 on timeout (a
    // bound for a hang, not for speed: qemu on a loaded machine runs
    // children many times slower).
    int reap(pid_t p, int timeout_ms = 120000) {
        for (int waited = 0;; waited += 1) {
            int st = 0;
            const pid_t r = waitpid(p, &st, WNOHANG);
            if (r == p) {
                forget(p);
                return WIFEXITED(st) ? WEXITSTATUS(st) : -WTERMSIG(st);
            }
            if (r < 0 || waited >= timeout_ms) return 1000;
            sleep_us(1000);
        }
    }
    void kill9(pid_t p) {
        kill(p, SIGKILL);
        EXPECT_EQ(reap(p), -SIGKILL);
    }
    void forget(pid_t p) {
        for (auto it = children_.begin(); it != children_.end(); ++it)
            if (*it == p) {
                children_.erase(it);
                break;
            }
    }
    // Wait (bounded) until slot s reaches `state` in this process's view.
    bool wait_slot_state(int s, chm_bp_slot_state state, int timeout_ms = 5000) {
        const std::uint64_t end = now_ns() + std::uint64_t(timeout_ms) * 1000000u;
        chm_bp_status_t st;
        while (now_ns() < end) {
            if (chm_bp_status(&st) == 0 && st.slot[s].state == state) return true;
            sleep_us(100);
        }
        return false;
    }
    // Run chimera-bpcheck on `file`; its output goes to *out.
    int bpcheck(const std::string& file, std::string* out) {
        const std::string cmd = std::string(CHM_BPCHECK) + " '" + file + "' 2>&1";
        FILE* f = popen(cmd.c_str(), "r");
        if (!f) return -1;
        char buf[512];
        out->clear();
        while (fgets(buf, sizeof buf, f)) *out += buf;
        const int st = pclose(f);
        return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
    }

    std::string dir_, path_;
    std::vector<pid_t> children_;
};

}  // namespace chm::test
