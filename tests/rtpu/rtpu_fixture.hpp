// Scaffolding of suite `rtpu`: a private directory and backplane per test
// under /dev/shm, real chimera-rtpu processes (and chimera commands) run
// with their output in files, every wait bounded, every child killed and
// reaped and every file removed in teardown, also when a test fails.
#pragma once

#include <gtest/gtest.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <dirent.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "chimera/bp.h"
#include "chimera/rtpu.h"
#include "../private_dir.hpp"
#include "lib/nap.hpp"

namespace chm::test {

inline std::uint64_t now_ms() {
    timespec ts{};
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return std::uint64_t(ts.tv_sec) * 1000u + std::uint64_t(ts.tv_nsec) / 1000000u;
}

using chm::nap_ms;  // lib/nap.hpp, shared with the library and the chimera tool

inline std::string read_file(const std::string& path) {
    std::ifstream f(path);
    std::stringstream s;
    s << f.rdbuf();
    return s.str();
}

inline int count_lines(const std::string& s) {
    int n = 0;
    for (char c : s) n += c == '\n';
    return n;
}

// What a finished command said.
struct Outcome {
    int status = -1;  // exit status, -signal, or 1000 when it had to be killed
    std::string out, err;
};

class RtpuTest : public ::testing::Test {
protected:
    void SetUp() override {
        dir_ = make_private_dir("chm-rtpu-");
        ASSERT_FALSE(dir_.empty()) << strerror(errno);
        bp_ = dir_ + "/test.bp";
        chm_rtpu_timeout_set(0);
    }
    void TearDown() override {
        // RTPUs that `chimera start` ran are not our children: kill every
        // process the table names.
        if (chm_bp_self() >= 0 || chm_bp_attach_host(bp_.c_str(), "teardown", nullptr) == 0) {
            chm_bp_status_t st;
            if (chm_bp_status(&st) == 0)
                for (std::uint32_t s = 0; s < st.slots; ++s)
                    if (int(s) != st.self && st.slot[s].pid > 0) kill(st.slot[s].pid, SIGKILL);
        }
        (void)(void)(void)chm_bp_leave();
        for (pid_t p : children_) {
            kill(p, SIGKILL);
            waitpid(p, nullptr, 0);
        }
        children_.clear();
        remove_private_dir(dir_);
    }

    // A backplane like chimera start makes (1 KiB records), and attach.
    void create(bool attach = true, std::uint32_t records = 32, std::uint32_t record_size = 1024,
                std::uint32_t common_size = 256 * 1024) {
        chm_bp_config_t c;
        chm_bp_config_init(&c);
        c.rtpu_slots = 8;
        c.ring_records = records;
        c.ring_record_size = record_size;
        c.local_window_size = 64 * 1024;
        c.common_size = common_size;
        c.registry_capacity = 32;
        ASSERT_EQ(chm_bp_create(bp_.c_str(), &c), 0) << chm_bp_last_error();
        if (attach) {
            ASSERT_EQ(chm_bp_attach_host(bp_.c_str(), "test", nullptr), 0) << chm_bp_last_error();
        }
    }

    // Start a process with output to files; tracked for teardown.
    pid_t spawn(const std::vector<std::string>& args, const std::string& out, const std::string& err) {
        std::fflush(nullptr);
        const pid_t p = fork();
        if (p == 0) {
            const int o = open(out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
            const int e = open(err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
            if (o >= 0) dup2(o, 1);
            if (e >= 0) dup2(e, 2);
            std::vector<char*> argv;
            for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
            argv.push_back(nullptr);
            execv(argv[0], argv.data());
            _exit(127);
        }
        EXPECT_GT(p, 0);
        if (p > 0) children_.push_back(p);
        return p;
    }

    // chimera-rtpu --backplane <ours> --rtpu n [extra...]; output in
    // <dir>/rtpu<n>.out / .err.
    pid_t start_rtpu(int n, const std::vector<std::string>& extra = {}) {
        std::vector<std::string> args = {CHIMERA_RTPU_BIN, "--backplane", bp_, "--rtpu", std::to_string(n)};
        args.insert(args.end(), extra.begin(), extra.end());
        return spawn(args, out_of(n), err_of(n));
    }
    std::string out_of(int n) { return dir_ + "/rtpu" + std::to_string(n) + ".out"; }
    std::string err_of(int n) { return dir_ + "/rtpu" + std::to_string(n) + ".err"; }

    // Wait (bounded) until slot n runs process `pid` and answers a ping.
    bool wait_serving(int n, pid_t pid, int timeout_ms = 10000) {
        const std::uint64_t end = now_ms() + std::uint64_t(timeout_ms);
        const std::uint64_t saved = chm_rtpu_timeout();
        chm_rtpu_timeout_set(200'000'000);
        bool ok = false;
        while (!ok && now_ms() < end) {
            chm_bp_status_t st;
            chm_rtpu_info_t info;
            ok = chm_bp_status(&st) == 0 && st.slot[n].state == CHM_BP_RUNNING && st.slot[n].pid == pid &&
                 chm_rtpu_ping(n, &info) == 0 && info.pid == pid;
            if (!ok) nap_ms(10);
        }
        chm_rtpu_timeout_set(saved);
        return ok;
    }

    bool wait_slot(int n, chm_bp_slot_state state, int timeout_ms = 5000) {
        const std::uint64_t end = now_ms() + std::uint64_t(timeout_ms);
        while (now_ms() < end) {
            chm_bp_status_t st;
            if (chm_bp_status(&st) == 0 && st.slot[n].state == state) return true;
            nap_ms(5);
        }
        return false;
    }

    // Wait (bounded) until `path` contains `text`.
    bool wait_text(const std::string& path, const std::string& text, int timeout_ms = 10000) {
        const std::uint64_t end = now_ms() + std::uint64_t(timeout_ms);
        while (now_ms() < end) {
            if (read_file(path).find(text) != std::string::npos) return true;
            nap_ms(10);
        }
        return false;
    }

    // The child's exit status, -signal, or 1000 after timeout_ms.
    int reap(pid_t p, int timeout_ms = 10000) {
        const std::uint64_t end = now_ms() + std::uint64_t(timeout_ms);
        for (;;) {
            int st = 0;
            const pid_t r = waitpid(p, &st, WNOHANG);
            if (r == p) {
                forget(p);
                return WIFEXITED(st) ? WEXITSTATUS(st) : -WTERMSIG(st);
            }
            if (r < 0 || now_ms() >= end) return 1000;
            nap_ms(2);
        }
    }
    void forget(pid_t p) {
        for (auto it = children_.begin(); it != children_.end(); ++it)
            if (*it == p) {
                children_.erase(it);
                return;
            }
    }

    // Run a command to its end (bounded; killed after timeout_ms).
    Outcome run(const std::vector<std::string>& args, int timeout_ms = 20000) {
        static int k = 0;
        const std::string out = dir_ + "/cmd" + std::to_string(++k) + ".out";
        const std::string err = dir_ + "/cmd" + std::to_string(k) + ".err";
        Outcome r;
        const pid_t p = spawn(args, out, err);
        r.status = reap(p, timeout_ms);
        r.out = read_file(out);
        r.err = read_file(err);
        unlink(out.c_str());
        unlink(err.c_str());
        return r;
    }
    Outcome chimera(std::vector<std::string> args, bool with_backplane = true) {
        args.insert(args.begin(), CHIMERA_BIN);
        if (with_backplane) args.insert(args.begin() + 2, {"--backplane", bp_});
        return run(args);
    }

    std::string dir_, bp_;
    std::vector<pid_t> children_;
};

}  // namespace chm::test
