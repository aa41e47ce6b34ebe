// The servo suite's fixture: a private backplane with RTPUs 1 and 2 run
// by real chimera-rtpu processes under this process's control, state
// variables "v" and "f", and the cycle logs the counter modules append to.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "chimera/chimera.h"
#include "../rtpu/rtpu_fixture.hpp"

namespace chm::test {

constexpr std::uint64_t kMs = 1'000'000;
constexpr int kLogMax = 16384;
struct CycleLog {
    std::uint32_t count;  // published after its entry (modules/counter.c)
    std::uint32_t pad;
    std::uint64_t k[kLogMax];
};
// The entries a running module has published so far: read once, and use
// only that many (a second read may count a cycle appended meanwhile).
inline std::uint32_t logged(const CycleLog* log) {
    const std::uint32_t n = __atomic_load_n(&log->count, __ATOMIC_ACQUIRE);
    return n < kLogMax ? n : kLogMax;
}

class Servo : public RtpuTest {
protected:
    void SetUp() override {
        RtpuTest::SetUp();
        chm_bp_config_t c;
        chm_bp_config_init(&c);
        c.rtpu_slots = 8;
        c.ring_records = 32;
        c.ring_record_size = 1024;
        c.local_window_size = 64 * 1024;
        c.common_size = 4 * 1024 * 1024;
        c.registry_capacity = 32;
        ASSERT_EQ(chm_bp_create(bp_.c_str(), &c), 0) << chm_bp_last_error();
        ASSERT_EQ(chm_bp_attach_host(bp_.c_str(), "controller", nullptr), 0) << chm_bp_last_error();
        for (int n : {1, 2}) {
            pid_[n] = start_rtpu(n);
            ASSERT_TRUE(wait_serving(n, pid_[n])) << read_file(err_of(n));
        }
        declare("v", CHM_SVAR_DOUBLE);
        declare("f", CHM_SVAR_DOUBLE);
        ASSERT_EQ(chm_servo_take(1u << 1 | 1u << 2), 0) << chm_servo_last_error();
    }
    static void declare(const char* name, chm_svar_type_t t) {
        chm_svar_decl_t d{name, t, 1, 1, ""};
        ASSERT_EQ(chm_svar_declare(&d), 0) << chm_bp_last_error();
    }
    CycleLog* make_log(const std::string& instance) {
        void* p = nullptr;
        EXPECT_EQ(chm_shm_create(("log." + instance).c_str(), sizeof(CycleLog), CHM_SHM_COMMON, &p), 0)
            << chm_bp_last_error();
        return static_cast<CycleLog*>(p);
    }
    // Spawn `path` as `name` on `rtpu`; the status of the call.
    int spawn(int rtpu, const char* path, const char* name, std::uint64_t period, chm_servo_module_t* out,
              std::vector<std::pair<const char*, double>> params = {}) {
        chm_servo_spawn_t s;
        chm_servo_spawn_init(&s);
        s.rtpu = rtpu;
        s.path = path;
        s.name = name;
        s.period_ns = period;
        s.priority = 5;
        std::vector<const char*> names;
        std::vector<double> values;
        for (auto& [k, v] : params) names.push_back(k), values.push_back(v);
        s.n_params = params.size();
        s.param_names = names.data();
        s.param_values = values.data();
        return chm_servo_spawn(&s, out);
    }
    chm_servo_status_t status(chm_servo_module_t m) {
        chm_servo_status_t st{};
        EXPECT_EQ(chm_servo_status(m, &st), 0) << chm_servo_last_error();
        return st;
    }
    // Wait (bounded) until m is in `state`.
    bool wait_state(chm_servo_module_t m, int state, int timeout_ms = 5000) {
        const std::uint64_t end = now_ms() + std::uint64_t(timeout_ms);
        while (now_ms() < end) {
            chm_servo_status_t st{};
            if (chm_servo_status(m, &st) == 0 && st.state == state) return true;
            nap_ms(1);
        }
        return false;
    }
    // chm_servo_switch, asked again while it is refused whole because a
    // commit came too late for its instant (-ETIME: a loaded machine) or
    // a module is still finishing its last cycle (-EALREADY), for up to
    // 60 s: a refused switch changed nothing. The last status otherwise.
    static int switch_until_done(const chm_servo_module_t* off, size_t n_off, const chm_servo_module_t* on,
                                 size_t n_on, std::uint64_t* at) {
        const std::uint64_t end = now_ms() + 60000;
        int r;
        while ((r = chm_servo_switch(off, n_off, on, n_on, 0, at)) == -ETIME || r == -EALREADY) {
            if (now_ms() > end) break;
            nap_ms(1);
        }
        return r;
    }
    static int on_until_done(chm_servo_module_t m) { return switch_until_done(nullptr, 0, &m, 1, nullptr); }
    static int off_until_done(chm_servo_module_t m) { return switch_until_done(&m, 1, nullptr, 0, nullptr); }
    // Start RTPU n so that it stops itself (SIGSTOP) the first time it
    // passes the named stop point (CHIMERA_STOP_AT).
    pid_t start_rtpu_stopping_at(int n, const char* point) {
        ::setenv("CHIMERA_STOP_AT", point, 1);
        const pid_t p = start_rtpu(n);
        ::unsetenv("CHIMERA_STOP_AT");
        return p;
    }
    static double get(const char* name) {
        double v = NAN;
        EXPECT_EQ(chm_svar_get(name, &v, sizeof v), 0);
        return v;
    }
    pid_t pid_[3] = {};
};

}  // namespace chm::test
