// Port conformance: a timer signal preempts a task at any instruction of
// preemptible code, another context runs and clobbers what it likes, and the
// task resumes with every register and its flags intact. A preemption that
// lands inside the C library is deferred instead.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <vector>

#include "port.hpp"
#include "regs_helpers.hpp"

#if CHM_PORT_HAS_PREEMPTION

namespace {

volatile std::uint64_t g_hooks = 0;
volatile bool g_preempt_on = true;
chm::port::Context g_hook_ctx, g_other_ctx;

bool tick_every_50us(std::uint64_t now) {
    chm::port::timer_arm_locked(now + 50000);
    return g_preempt_on;
}

// Another task: dirties FP/SIMD and integer registers through ordinary
// compiled code and the C library, then gives the CPU back.
void other_task(void*) {
    static unsigned char buf[4096];
    volatile double acc = 0;
    for (unsigned i = 1;; ++i) {
        for (unsigned k = 1; k < 64; ++k) acc = acc + std::sqrt(double(k * i)) * 1.5;
        std::memset(buf, int(i), sizeof buf);
        chm::port::context_switch(&g_other_ctx, &g_hook_ctx);
    }
}

void hook() {
    EXPECT_EQ(chm::port::g_irq.nest, 1u) << "the trampoline runs with the mask held";
    g_hooks = g_hooks + 1;
    chm::port::context_switch(&g_hook_ctx, &g_other_ctx);
    // What the kernel does when the preempted task runs again: release the
    // mask and take a tick that arrived while it was held (here: re-arm the
    // periodic timer). Clear first, test after: a tick landing between a
    // test and the clear would only be recorded, leaving the one-shot timer
    // unarmed for good -- under qemu, which delivers signals at translation
    // block boundaries, that window is hit about once in twenty runs.
    for (;;) {
        chm::port::g_irq.nest = 0;
        __atomic_signal_fence(__ATOMIC_SEQ_CST);
        if (!chm::port::g_irq.pending) break;
        chm::port::g_irq.nest = 1;
        __atomic_signal_fence(__ATOMIC_SEQ_CST);
        chm::port::g_irq.pending = 0;
        chm::port::timer_arm_locked(chm::port::now_ns() + 50000);
    }
}

class PortPreempt : public ::testing::Test {
protected:
    void SetUp() override {
        stack_.resize(64 * 1024);
        chm::port::context_init(&g_other_ctx, stack_.data(), stack_.size(), other_task, nullptr);
        chm::port::chm_port_preempt_hook = hook;
        g_hooks = 0;
        g_preempt_on = true;
        ASSERT_EQ(chm::port::timer_init(tick_every_50us), 0);
        chm::port::timer_arm_locked(chm::port::now_ns() + 50000);
    }
    void TearDown() override {
        chm::port::timer_fini();
        chm::port::chm_port_preempt_hook = nullptr;
    }
    std::vector<unsigned char> stack_;
};

TEST_F(PortPreempt, EveryRegisterSurvivesPreemption) {
    constexpr int kRegs = kChmPreemptRegs;
    std::uint64_t out[kRegs + 1];
    std::uint64_t total_hooks = 0;
    // Spin until enough preemptions landed inside the spin (bounded).
    for (int round = 0; round < 200 && total_hooks < 200; ++round) {
        const std::uint64_t before = g_hooks;
        std::memset(out, 0, sizeof out);
        chm_test_preempt_spin(20000000, out);
        total_hooks += g_hooks - before;
        for (int i = 0; i < kRegs; ++i)
            ASSERT_EQ(out[i], chm_test_preempt_patterns[i]) << "register #" << i << " in round " << round;
        ASSERT_EQ(out[kRegs] & kChmPreemptFlagsMask, kChmPreemptFlagsExpected)
            << "condition flags (carry among them) lost in round " << round;
    }
    EXPECT_GE(total_hooks, 200u) << "the timer must actually have preempted the spin";
}

TEST_F(PortPreempt, PreemptionInsideTheCLibraryIsDeferred) {
    const std::uint64_t deferred_before = chm::port::deferred_preemption_count();
    std::vector<unsigned char> big(16 << 20);
    std::uint64_t out[kChmPreemptRegs + 1];
    // Alternate long stays in libc with stays in preemptible code, until
    // both kinds of landing were seen (bounded).
    for (int i = 0; i < 2000; ++i) {
        std::memset(big.data(), i, big.size());
        chm_test_preempt_spin(200000, out);
        if (i > 20 && g_hooks > 0 && chm::port::deferred_preemption_count() > deferred_before) break;
    }
    EXPECT_GT(chm::port::deferred_preemption_count(), deferred_before)
        << "ticks that land in memset must be deferred, not taken";
    EXPECT_GT(g_hooks, 0u) << "deferred ticks are retried and taken outside libc";
}

}  // namespace

#else
TEST(PortPreempt, NotYetImplementedOnThisPort) { GTEST_SKIP() << chm::port::kArchName; }
#endif
