// The timeout convention (chimera/kernel.h, "Timeouts") on the local
// semaphore and chm_task_join, on the virtual clock where every wait is
// exact: CHM_NO_WAIT fails at once with -EAGAIN, a positive timeout ends
// with -ETIMEDOUT after exactly that long, CHM_FOREVER waits for the V, and
// chm_sem_p_until waits until its absolute deadline (one already past does
// not wait).
#include <cerrno>

#include "kernel_fixture.hpp"

namespace chm::test {
namespace {

chm_sem_t g_sem;
std::uint64_t g_v_at = 0;  // when the giver gave its unit

std::uint64_t g_limit = 0;
int g_result = -1000;
std::uint64_t g_woke_at = 0;

// Gives one unit after consuming `arg` ns of CPU (the waiter runs first:
// higher priority).
void give_later(void* arg) {
    chm_time_consume(reinterpret_cast<std::uintptr_t>(arg));
    g_v_at = chm_time_now();
    EXPECT_EQ(chm_sem_v(&g_sem), 0);
}

class Timeouts : public KernelTest {
protected:
    // The waiter (priority 2) waits with g_limit; the giver Vs after 9 ms
    // of CPU.
    void run_waiter_and_giver(void (*waiter)(void*)) {
        g_result = -1000;
        g_v_at = g_woke_at = 0;
        ASSERT_EQ(chm_sem_init(&g_sem, CHM_SEM_BINARY, 0, 0), 0);
        spawn(waiter, nullptr, "waiter", 2);
        spawn(give_later, reinterpret_cast<void*>(std::uintptr_t(9 * kMs)), "giver", 1);
        ASSERT_EQ(chm_kernel_run(), 0);
    }
};

void no_wait_and_positive(void*) {
    const std::uint64_t t0 = chm_time_now();
    EXPECT_EQ(chm_sem_p_timed(&g_sem, CHM_NO_WAIT), -EAGAIN);
    EXPECT_EQ(chm_time_now(), t0) << "CHM_NO_WAIT does not wait";
    EXPECT_EQ(chm_sem_p_timed(&g_sem, 3 * kMs), -ETIMEDOUT);
    EXPECT_EQ(chm_time_now() - t0, 3 * kMs) << "the timeout is exact on the virtual clock";
    EXPECT_EQ(chm_sem_v(&g_sem), 0);
    EXPECT_EQ(chm_sem_p_timed(&g_sem, CHM_NO_WAIT), 0) << "a free unit is taken without waiting";
}

TEST_F(Timeouts, SemNoWaitFailsAtOnceAndAPositiveTimeoutIsExact) {
    start(CHM_SCHED_FIXED);
    ASSERT_EQ(chm_sem_init(&g_sem, CHM_SEM_BINARY, 0, 0), 0);
    spawn(no_wait_and_positive, nullptr, "t", 2);
    ASSERT_EQ(chm_kernel_run(), 0);
}

void timed_waiter(void*) {
    g_result = chm_sem_p_timed(&g_sem, g_limit);
    g_woke_at = chm_time_now();
}

void until_waiter(void*) {
    g_result = chm_sem_p_until(&g_sem, g_limit);
    g_woke_at = chm_time_now();
}

TEST_F(Timeouts, SemForeverWaitsForTheV) {
    start(CHM_SCHED_FIXED);
    g_limit = CHM_FOREVER;
    run_waiter_and_giver(timed_waiter);
    EXPECT_EQ(g_result, 0);
    EXPECT_EQ(g_v_at, 9 * kMs);
    EXPECT_EQ(g_woke_at, 9 * kMs);
}

void late_timed_waiter(void*) {
    chm_time_consume(kMs);
    timed_waiter(nullptr);
}

TEST_F(Timeouts, SemHugeTimeoutSaturatesInsteadOfWrapping) {
    start(CHM_SCHED_FIXED);
    g_limit = CHM_FOREVER - 1;  // now (1 ms) + this overflows: no limit, not a past deadline
    run_waiter_and_giver(late_timed_waiter);
    EXPECT_EQ(g_result, 0);
    EXPECT_EQ(g_woke_at, 10 * kMs);
}

TEST_F(Timeouts, SemUntilTimesOutExactlyAtTheDeadline) {
    start(CHM_SCHED_FIXED);
    g_limit = 4 * kMs;  // before the V at 9 ms
    run_waiter_and_giver(until_waiter);
    EXPECT_EQ(g_result, -ETIMEDOUT);
    EXPECT_EQ(g_woke_at, 4 * kMs) << "the deadline is exact on the virtual clock";
}

TEST_F(Timeouts, SemUntilReturnsAtTheVBeforeItsDeadline) {
    start(CHM_SCHED_FIXED);
    g_limit = 20 * kMs;
    run_waiter_and_giver(until_waiter);
    EXPECT_EQ(g_result, 0);
    EXPECT_EQ(g_woke_at, 9 * kMs);
}

TEST_F(Timeouts, SemUntilForeverWaitsForTheV) {
    start(CHM_SCHED_FIXED);
    g_limit = CHM_FOREVER;
    run_waiter_and_giver(until_waiter);
    EXPECT_EQ(g_result, 0);
    EXPECT_EQ(g_woke_at, 9 * kMs);
}

void past_deadline(void*) {
    chm_time_consume(5 * kMs);
    const std::uint64_t t0 = chm_time_now();
    EXPECT_EQ(chm_sem_p_until(&g_sem, t0 - kMs), -ETIMEDOUT) << "a past deadline";
    EXPECT_EQ(chm_sem_p_until(&g_sem, t0), -ETIMEDOUT) << "a deadline reached now";
    EXPECT_EQ(chm_sem_p_until(&g_sem, 0), -ETIMEDOUT);
    EXPECT_EQ(chm_time_now(), t0) << "a deadline already past does not wait";
    EXPECT_EQ(chm_sem_v(&g_sem), 0);
    EXPECT_EQ(chm_sem_p_until(&g_sem, t0 - kMs), 0) << "a free unit is still taken";
    EXPECT_EQ(chm_time_now(), t0);
}

TEST_F(Timeouts, SemUntilAPastDeadlineDoesNotWait) {
    start(CHM_SCHED_FIXED);
    ASSERT_EQ(chm_sem_init(&g_sem, CHM_SEM_COUNTING, 0, 0), 0);
    spawn(past_deadline, nullptr, "t", 2);
    ASSERT_EQ(chm_kernel_run(), 0);
}

// A periodic loop against fixed deadlines: a V at 3, 7 and 11 ms, waits
// until each 2 ms mark. The deadlines do not drift however the waits end.
std::uint64_t g_marks[6];
int g_outcomes[6];

void marker(void*) {
    for (int i = 0; i < 6; ++i) {
        const std::uint64_t deadline = std::uint64_t(i + 1) * 2 * kMs;
        g_outcomes[i] = chm_sem_p_until(&g_sem, deadline);
        g_marks[i] = chm_time_now();
    }
}

void ticker(void*) {
    for (int i = 0; i < 3; ++i) {
        chm_task_pause_until(std::uint64_t(3 + 4 * i) * kMs);
        EXPECT_EQ(chm_sem_v(&g_sem), 0);
    }
}

TEST_F(Timeouts, SemUntilInALoopKeepsItsDeadlines) {
    start(CHM_SCHED_FIXED);
    ASSERT_EQ(chm_sem_init(&g_sem, CHM_SEM_COUNTING, 0, 0), 0);
    spawn(marker, nullptr, "marker", 2);
    spawn(ticker, nullptr, "ticker", 1);
    ASSERT_EQ(chm_kernel_run(), 0);
    // Vs at 3, 7, 11; deadlines 2, 4, 6, 8, 10, 12.
    const int want[6] = {-ETIMEDOUT, 0, -ETIMEDOUT, 0, -ETIMEDOUT, 0};
    const std::uint64_t at[6] = {2 * kMs, 3 * kMs, 6 * kMs, 7 * kMs, 10 * kMs, 11 * kMs};
    for (int i = 0; i < 6; ++i) {
        EXPECT_EQ(g_outcomes[i], want[i]) << "wait " << i;
        EXPECT_EQ(g_marks[i], at[i]) << "wait " << i;
    }
}

void joins(void*) {
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = "child";
    a.priority = 1;
    a.joinable = 1;
    chm_tid_t id = CHM_TID_NONE;
    ASSERT_EQ(chm_task_spawn(&id, give_later, reinterpret_cast<void*>(std::uintptr_t(7 * kMs)), &a), 0);
    const std::uint64_t t0 = chm_time_now();
    EXPECT_EQ(chm_task_join(id, CHM_NO_WAIT, nullptr), -EAGAIN);
    EXPECT_EQ(chm_time_now(), t0) << "CHM_NO_WAIT does not wait";
    EXPECT_EQ(chm_task_join(id, 2 * kMs, nullptr), -ETIMEDOUT);
    EXPECT_EQ(chm_time_now() - t0, 2 * kMs);
    EXPECT_EQ(chm_task_join(id, CHM_FOREVER, nullptr), 0);
    EXPECT_EQ(chm_time_now() - t0, 7 * kMs);
}

TEST_F(Timeouts, JoinNoWaitPositiveAndForever) {
    start(CHM_SCHED_FIXED);
    ASSERT_EQ(chm_sem_init(&g_sem, CHM_SEM_COUNTING, 0, 0), 0);
    spawn(joins, nullptr, "joiner", 2);
    ASSERT_EQ(chm_kernel_run(), 0);
}

}  // namespace
}  // namespace chm::test
