// A kernel per test: init with a policy and clock, run, tear down.
#pragma once

#include <gtest/gtest.h>

#include <cstdint>
#include <cstdlib>
#include <string>
#include <vector>

#include "chimera/chimera.h"

namespace chm::test {

inline constexpr uint64_t kMs = 1000000;
inline constexpr uint64_t kUs = 1000;

// A number from the environment (a seed, a count), or `dflt` when unset.
inline std::uint64_t env_or(const char* name, std::uint64_t dflt) {
    const char* v = std::getenv(name);
    return v && *v ? std::strtoull(v, nullptr, 10) : dflt;
}

struct Event {
    uint64_t t;
    std::string who;
    bool operator==(const Event&) const = default;
};

inline std::ostream& operator<<(std::ostream& o, const Event& e) {
    return o << e.who << "@" << e.t;
}

class KernelTest : public ::testing::Test {
protected:
    void start(chm_sched_policy policy, bool virtual_clock = true, uint64_t quantum = 0,
               const chm_sched_ops_t* user = nullptr, void* user_arg = nullptr) {
        chm_kernel_config_t cfg;
        chm_kernel_config_init(&cfg);
        cfg.policy = policy;
        cfg.virtual_clock = virtual_clock;
        cfg.quantum_ns = quantum;
        cfg.user_sched = user;
        cfg.user_sched_arg = user_arg;
        cfg.timer_lead_ns = lead_;
        ASSERT_EQ(chm_kernel_init(&cfg), 0);
        started_ = true;
    }
    std::int64_t lead_ = CHM_TIMER_LEAD_AUTO;  // set before start()
    void TearDown() override {
        if (started_) chm_kernel_fini();
    }
    chm_tid_t spawn(void (*fn)(void*), void* arg, const char* name, int prio = 0,
                    uint64_t period = 0, uint64_t wcet = 0, int critical = 0,
                    uint64_t deadline = 0) {
        chm_task_attr_t a;
        chm_task_attr_init(&a);
        a.name = name;
        a.priority = prio;
        a.period_ns = period;
        a.wcet_ns = wcet;
        a.critical = critical;
        a.deadline_ns = deadline;
        chm_tid_t id = CHM_TID_NONE;
        EXPECT_EQ(chm_task_spawn(&id, fn, arg, &a), 0) << name;
        return id;
    }
    bool started_ = false;
};

}  // namespace chm::test
