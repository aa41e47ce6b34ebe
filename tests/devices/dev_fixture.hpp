// Devices tests: a private simulation directory per test (under /dev/shm),
// removed with everything in it afterwards, and helpers for child processes
// whose every wait is bounded.
#pragma once

#include <gtest/gtest.h>
#include <dirent.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <string>

#include "chimera/dev.h"
#include "chimera/sensor.h"
#include "sim.h"

namespace chm::test {

class SimDirTest : public ::testing::Test {
protected:
    void SetUp() override {
        char tmpl[] = "/dev/shm/chimera-devtest-XXXXXX";
        ASSERT_NE(mkdtemp(tmpl), nullptr);
        dir_ = tmpl;
        setenv("CHIMERA_SIM_DIR", dir_.c_str(), 1);
        open_before_ = chm_dev_open_count();
    }
    void TearDown() override {
        for (const std::string& n : registered_) chm_sim_unregister(n.c_str());
        for (pid_t p : children_) {
            kill(p, SIGKILL);
            waitpid(p, nullptr, 0);
        }
        if (DIR* d = opendir(dir_.c_str())) {
            while (const dirent* e = readdir(d))
                if (e->d_name[0] != '.') unlink((dir_ + "/" + e->d_name).c_str());
            closedir(d);
        }
        rmdir(dir_.c_str());
        unsetenv("CHIMERA_SIM_DIR");
        EXPECT_EQ(chm_dev_open_count(), open_before_) << "descriptors leaked";
    }
    std::string path(const char* name) const { return dir_ + "/" + name; }
    // Register `file` as device `name`; unregistered at teardown.
    void reg(const char* name, const char* file) {
        ASSERT_EQ(chm_sim_register(name, path(file).c_str()), 0) << name;
        registered_.push_back(name);
    }
    // Fork a child running fn(); killed at teardown if still alive.
    template <class F> pid_t spawn_child(F fn) {
        std::fflush(nullptr);
        const pid_t p = fork();
        if (p == 0) {
            alarm(30);  // never outlive a stuck test
            _exit(fn());
        }
        children_.push_back(p);
        return p;
    }
    // Exit status of a child, or -1 if it did not end within timeout_ms.
    int wait_child(pid_t p, int timeout_ms = 20000) {
        for (int waited = 0; waited < timeout_ms; waited += 5) {
            int st = 0;
            if (waitpid(p, &st, WNOHANG) == p) {
                std::erase(children_, p);
                return WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
            }
            usleep(5000);
        }
        return -1;
    }
    std::string dir_;
    std::vector<std::string> registered_;
    std::vector<pid_t> children_;
    int open_before_ = 0;
};

// Wait until `fd` is readable (bounded).
inline bool readable_within(int fd, int timeout_ms) {
    pollfd p{fd, POLLIN, 0};
    return poll(&p, 1, timeout_ms) == 1;
}

inline void drain(int fd) {
    char b[64];
    while (read(fd, b, sizeof b) > 0) {}
}

}  // namespace chm::test
