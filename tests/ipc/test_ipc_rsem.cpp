// Remote semaphores (chimera/rsem.h) with real processes: host threads on
// the futex, RTPU tasks that park only themselves, priority hand-off, a
// waiter killed while blocked. Every wait is bounded; nothing asserts speed.
#include <cerrno>

#include "chimera/chimera.h"
#include "chimera/rsem.h"
#include "chimera/shm.h"
#include "ipc/wake/wake.hpp"
#include "port.hpp"
#include "../kernel/gap_ticker.hpp"
#include "ipc_fixture.hpp"
#include "rsem_fixture.hpp"
#include "rtpu_child.hpp"

namespace chm::test {
namespace {

constexpr int64_t kWait = 10'000'000'000;  // 10 s: only a broken wake-up takes this long

class Rsem : public RsemTest {
protected:
    void SetUp() override {
        IpcTest::SetUp();
        create();
    }
    void attach_host() { ASSERT_EQ(chm_bp_attach_host(path_.c_str(), "test", nullptr), 0) << chm_bp_last_error(); }
};

volatile int g_result = -1000;
uint64_t g_waited = 0;

void p_waiter(void*) {
    chm_rsem_t* s = nullptr;
    if (chm_rsem_open("sem", &s) != 0) {
        g_result = -999;
    } else {
        GapTicker::max_gap = 0;
        const uint64_t t0 = chm_time_now();
        g_result = chm_rsem_p_timed(s, kWait);
        g_waited = chm_time_now() - t0;
    }
    GapTicker::stop = true;
}

TEST_F(Rsem, AHostThreadBlockedInPIsWokenByAnotherProcess) {
    attach_host();
    chm_rsem_t* s = make("sem");
    const std::string path = path_;
    const pid_t child = spawn([path] {
        if (chm_bp_attach_host(path.c_str(), "child", nullptr) != 0) return 90;
        chm_rsem_t* c = nullptr;
        if (chm_rsem_open("sem", &c) != 0) return 91;
        return chm_rsem_p_timed(c, kWait) == 0 ? 0 : 92;
    });
    ASSERT_TRUE(until_waiting(s, 1));
    ASSERT_EQ(chm_rsem_v(s), 0);
    EXPECT_EQ(reap(child), 0);
    EXPECT_EQ(chm_rsem_value(s), 0);
    EXPECT_EQ(chm_rsem_waiting(s), 0);
}

TEST_F(Rsem, PParksOnlyTheTaskAndAHostVWakesIt) {
    attach_host();
    chm_rsem_t* s = make("sem");
    const std::string path = path_;
    const pid_t child = spawn([path] {
        const int r = run_rtpu(path, 1, [] {
            return spawn_task(GapTicker::body, nullptr, "ticker", 5, 2000000) != CHM_TID_NONE &&
                   spawn_task(p_waiter, nullptr, "waiter", 1) != CHM_TID_NONE;
        });
        if (r != 0) return r;
        if (g_result != 0) return 50;
        // The 2 ms ticker kept running while the waiter was parked.
        return GapTicker::max_gap * 3 < g_waited ? 0 : 51;
    });
    ASSERT_TRUE(until_waiting(s, 1));
    sleep_us(100000);
    ASSERT_EQ(chm_rsem_v(s), 0);
    EXPECT_EQ(reap(child), 0) << "50: P failed; 51: the RTPU stood still while its task waited";
}

void v_after_waiter(void*) {
    chm_rsem_t* s = nullptr;
    if (chm_rsem_open("sem", &s) != 0) {
        g_result = -999;
        return;
    }
    const uint64_t end = chm_time_now() + kWait;
    while (chm_rsem_waiting(s) < 1 && chm_time_now() < end) chm_task_pause_until(chm_time_now() + 1000000);
    g_result = chm_rsem_v(s);
}

TEST_F(Rsem, ATaskOnOneRtpuWakesATaskOnAnother) {
    attach_host();
    chm_rsem_t* s = make("sem");
    const std::string path = path_;
    const pid_t waiter = spawn([path] {
        const int r = run_rtpu(path, 1, [] { return spawn_task(p_waiter, nullptr, "waiter", 1) != CHM_TID_NONE; });
        return r ? r : (g_result == 0 ? 0 : 50);
    });
    const pid_t giver = spawn([path] {
        const int r = run_rtpu(path, 2, [] { return spawn_task(v_after_waiter, nullptr, "giver", 1) != CHM_TID_NONE; });
        return r ? r : (g_result == 0 ? 0 : 50);
    });
    EXPECT_EQ(reap(giver), 0);
    EXPECT_EQ(reap(waiter), 0);
    EXPECT_EQ(chm_rsem_value(s), 0);
}

// Two tasks of one RTPU wait; the less urgent one arrived first. Each V
// must go to the most urgent waiter.
volatile int g_order[2];
volatile int g_n_woken = 0;
void ranked_waiter(void* arg) {
    chm_rsem_t* s = nullptr;
    (void)chm_rsem_open("sem", &s);
    if (chm_rsem_p_timed(s, kWait) == 0) {
        const int k = g_n_woken;
        g_order[k] = int(reinterpret_cast<intptr_t>(arg));
        g_n_woken = k + 1;
    }
}
void late_urgent(void*) {
    chm_task_pause_until(chm_time_now() + 20000000);  // arrives second
    ranked_waiter(reinterpret_cast<void*>(9));
}

TEST_F(Rsem, VHandsTheSemaphoreToTheMostUrgentWaiterFirst) {
    attach_host();
    chm_rsem_t* s = make("sem");
    const std::string path = path_;
    const pid_t child = spawn([path] {
        const int r = run_rtpu(path, 1, [] {
            return spawn_task(ranked_waiter, reinterpret_cast<void*>(1), "low", 1) != CHM_TID_NONE &&
                   spawn_task(late_urgent, nullptr, "high", 9) != CHM_TID_NONE;
        });
        if (r) return r;
        return g_n_woken == 2 && g_order[0] == 9 && g_order[1] == 1 ? 0 : 60 + g_order[0];
    });
    ASSERT_TRUE(until_waiting(s, 2));
    ASSERT_EQ(chm_rsem_v(s), 0);
    ASSERT_EQ(chm_rsem_v(s), 0);
    EXPECT_EQ(reap(child), 0) << "the low-priority waiter was served first";
}

TEST_F(Rsem, AWaiterKilledWhileBlockedIsRemovedAndItsVGoesToTheCount) {
    attach_host();
    chm_rsem_t* s = make("sem");
    const std::string path = path_;
    const pid_t child = spawn([path] {
        if (chm_bp_attach_host(path.c_str(), "victim", nullptr) != 0) return 90;
        chm_rsem_t* c = nullptr;
        if (chm_rsem_open("sem", &c) != 0) return 91;
        (void)chm_rsem_p_timed(c, kWait);
        return 92;
    });
    ASSERT_TRUE(until_waiting(s, 1));
    kill9(child);
    ASSERT_TRUE(until_waiting(s, 0)) << "the dead waiter was not removed";
    ASSERT_EQ(chm_rsem_v(s), 0);
    EXPECT_EQ(chm_rsem_value(s), 1) << "the V went to a dead waiter";
}

TEST_F(Rsem, CountsTimeoutsAndBadInput) {
    chm_rsem_t* s = nullptr;
    EXPECT_EQ(chm_rsem_create("x", CHM_SEM_COUNTING, 0, CHM_SHM_COMMON, &s), -ENOTCONN);
    attach_host();
    EXPECT_EQ(chm_rsem_create("b", CHM_SEM_BINARY, 2, CHM_SHM_COMMON, &s), -EINVAL);
    EXPECT_EQ(chm_rsem_create(nullptr, CHM_SEM_BINARY, 0, CHM_SHM_COMMON, &s), -EINVAL);
    EXPECT_EQ(chm_rsem_create("b", CHM_SEM_BINARY, 0, 99, &s), -ECHRNG);
    chm_rsem_t* c = make("count", CHM_SEM_COUNTING, 2);
    EXPECT_EQ(chm_rsem_create("count", CHM_SEM_COUNTING, 0, CHM_SHM_COMMON, &s), -EEXIST);
    EXPECT_EQ(chm_rsem_try_p(c), 0);
    EXPECT_EQ(chm_rsem_try_p(c), 0);
    EXPECT_EQ(chm_rsem_try_p(c), -EAGAIN);
    const uint64_t t0 = now_ns();
    EXPECT_EQ(chm_rsem_p_timed(c, 20000000), -ETIMEDOUT);
    EXPECT_GE(now_ns() - t0, 20000000u);
    EXPECT_EQ(chm_rsem_waiting(c), 0) << "a timed-out waiter stayed listed";
    chm_rsem_t* b = make("bin", CHM_SEM_BINARY, 0);
    EXPECT_EQ(chm_rsem_v(b), 0);
    EXPECT_EQ(chm_rsem_v(b), 0);
    EXPECT_EQ(chm_rsem_value(b), 1) << "a binary semaphore counts to 1";
    EXPECT_EQ(chm_rsem_open("nope", &s), -ENOENT);
    int not_a_sem = 0;
    EXPECT_EQ(chm_rsem_v(reinterpret_cast<chm_rsem_t*>(&not_a_sem)), -EINVAL);
    EXPECT_EQ(chm_rsem_destroy("count"), 0);
    EXPECT_EQ(chm_rsem_open("count", &s), -ENOENT);
}

}  // namespace
}  // namespace chm::test
