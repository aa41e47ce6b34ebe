// Port conformance: the one-shot timer fires in order, never early; idle
// sleeps until it; the timer signal never reaches a foreign thread.
#include <gtest/gtest.h>

#include <atomic>
#include <csignal>
#include <ctime>
#include <thread>

#include "port.hpp"

namespace {

constexpr int kFires = 20;
std::uint64_t g_armed[kFires + 1];
std::uint64_t g_fired[kFires];
volatile int g_count = 0;

bool on_tick(std::uint64_t now) {
    const int i = g_count;
    if (i >= kFires) return false;
    g_fired[i] = now;
    g_count = i + 1;
    if (i + 1 < kFires) {
        // Alternate short and longer gaps (50 µs .. 1 ms).
        g_armed[i + 1] = now + ((i % 2) ? 50000 : 1000000);
        chm::port::timer_arm_locked(g_armed[i + 1]);
    }
    return false;
}

void sleep_a_bit() {
    timespec ts{0, 200000};
    nanosleep(&ts, nullptr);
}

bool wait_for(int n, double seconds) {
    const std::uint64_t end = chm::port::now_ns() + std::uint64_t(seconds * 1e9);
    while (g_count < n && chm::port::now_ns() < end) sleep_a_bit();
    return g_count >= n;
}

class PortTimer : public ::testing::Test {
protected:
    void SetUp() override { ASSERT_EQ(chm::port::timer_init(on_tick), 0); g_count = 0; }
    void TearDown() override { chm::port::timer_fini(); }
};

TEST_F(PortTimer, OneShotFiresInOrderAndNeverEarly) {
    g_armed[0] = chm::port::now_ns() + 1000000;
    chm::port::timer_arm_locked(g_armed[0]);
    ASSERT_TRUE(wait_for(kFires, 20.0)) << "only " << g_count << " of " << kFires << " fired";
    for (int i = 0; i < kFires; ++i) {
        EXPECT_GE(g_fired[i], g_armed[i]) << "fire " << i << " came early";
        if (i) { EXPECT_GT(g_fired[i], g_fired[i - 1]); }
    }
}

TEST_F(PortTimer, RearmingReplacesTheEarlierSetting) {
    const std::uint64_t now = chm::port::now_ns();
    chm::port::timer_arm_locked(now + 2000000);
    g_armed[0] = now + 40000000;  // re-armed later: the 2 ms setting is gone
    chm::port::timer_arm_locked(g_armed[0]);
    // Stop the chain after the first fire.
    g_count = kFires - 1;
    ASSERT_TRUE(wait_for(kFires, 20.0));
    EXPECT_GE(g_fired[kFires - 1], g_armed[0]);
}

TEST_F(PortTimer, IdleSleepsUntilTheTimerWithTheMaskHeld) {
    chm::port::irq_disable();
    const std::uint64_t start = chm::port::now_ns();
    g_count = kFires - 1;  // a single fire, then no re-arm
    chm::port::timer_arm_locked(start + 5000000);
    while (!chm::port::g_irq.pending) chm::port::idle_wait_locked();
    const std::uint64_t woke = chm::port::now_ns();
    EXPECT_GE(woke - start, 5000000u);
    // The tick was only recorded while masked; restoring takes it.
    static int hook_runs;
    static std::uint32_t hook_why;
    hook_runs = 0;
    hook_why = 0;
    chm::port::irq_set_pending_hook([](std::uint32_t why) {
        ++hook_runs;
        hook_why |= why;
    });
    chm::port::irq_restore();
    EXPECT_EQ(hook_runs, 1);
    EXPECT_EQ(hook_why, chm::port::kPendingTick);
    EXPECT_FALSE(chm::port::g_irq.pending);
    chm::port::irq_set_pending_hook(nullptr);
}

TEST_F(PortTimer, IdleWakeFromAnotherThread) {
    chm::port::irq_disable();
    std::thread waker([] {
        timespec ts{0, 3000000};
        nanosleep(&ts, nullptr);
        chm::port::idle_wake();
    });
    const std::uint64_t start = chm::port::now_ns();
    chm::port::idle_wait_locked();
    EXPECT_GE(chm::port::now_ns() - start, 1000000u);
    waker.join();
    chm::port::irq_restore();
}

TEST_F(PortTimer, ForeignThreadNeverReceivesTheTimerSignal) {
    std::atomic<bool> stop{false};
    std::thread foreign([&] {
        // The foreign thread deliberately unblocks the timer signal.
        sigset_t set;
        sigemptyset(&set);
        sigaddset(&set, chm::port::timer_signal());
        pthread_sigmask(SIG_UNBLOCK, &set, nullptr);
        while (!stop.load()) sleep_a_bit();
    });
    const std::uint64_t before = chm::port::stray_signal_count();
    g_armed[0] = chm::port::now_ns() + 100000;
    chm::port::timer_arm_locked(g_armed[0]);
    ASSERT_TRUE(wait_for(kFires, 20.0));
    stop = true;
    foreign.join();
    EXPECT_EQ(chm::port::stray_signal_count(), before);
}

}  // namespace
