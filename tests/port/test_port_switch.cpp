// Port conformance: context switching (ring, registers, alignment, FP state).
#include <gtest/gtest.h>

#include <cfenv>
#include <cstdint>
#include <cstdlib>
#include <vector>

#include "port.hpp"
#include "regs_helpers.hpp"

namespace {

using chm::port::Context;

struct Stack {
    explicit Stack(std::size_t n) : bytes(n) {}
    void* lo() { return bytes.data(); }
    std::size_t size() const { return bytes.size(); }
    alignas(16) std::vector<unsigned char> bytes;
};

// ---- a ring of N contexts passing control round-robin
constexpr int kRing = 8;
constexpr int kLaps = 1000;
Context g_main;
Context g_ring[kRing];
std::vector<int> g_trace;

void ring_entry(void* arg) {
    const int me = static_cast<int>(reinterpret_cast<std::intptr_t>(arg));
    for (;;) {
        g_trace.push_back(me);
        const bool last = (me == kRing - 1);
        if (last && g_trace.size() >= std::size_t(kRing * kLaps))
            chm::port::context_switch(&g_ring[me], &g_main);
        else
            chm::port::context_switch(&g_ring[me], &g_ring[(me + 1) % kRing]);
    }
}

TEST(PortSwitch, RingOfContextsRunsRoundRobin) {
    std::vector<Stack> stacks;
    stacks.reserve(kRing);
    g_trace.clear();
    g_trace.reserve(kRing * kLaps);
    for (int i = 0; i < kRing; ++i) {
        stacks.emplace_back(32 * 1024);
        chm::port::context_init(&g_ring[i], stacks[i].lo(), stacks[i].size(), ring_entry,
                                reinterpret_cast<void*>(std::intptr_t(i)));
    }
    chm::port::context_switch(&g_main, &g_ring[0]);
    ASSERT_EQ(g_trace.size(), std::size_t(kRing * kLaps));
    for (std::size_t i = 0; i < g_trace.size(); ++i)
        ASSERT_EQ(g_trace[i], int(i % kRing)) << "at step " << i;
}

TEST(PortSwitch, CalleeSavedRegistersSurviveASwitch) {
    Stack stack(32 * 1024);
    void* checker_sp = nullptr;
    Context clobber;
    ChmTestClobberArgs args{&clobber.sp, &checker_sp};
    chm::port::context_init(&clobber, stack.lo(), stack.size(), chm_test_clobber_entry, &args);
    for (std::uint64_t seed = 0x100; seed < 0x100 + 64; seed += 8) {
        int bad = chm_test_switch_check(&checker_sp, clobber.sp, seed);
        ASSERT_EQ(bad, 0) << "register #" << bad << " changed across the switch";
    }
}

TEST(PortSwitch, StackAlignedAtEntryAsTheAbiRequires) {
    // Offsets 2 and 6 misalign even a 4-byte ABI (m68k); 8, 24 and 40 a
    // 16-byte one.
    for (std::size_t offset : {0u, 2u, 4u, 6u, 8u, 16u, 24u, 40u}) {
        Stack stack(16 * 1024 + 64);
        Context probe_ctx;
        void* back = nullptr;
        ChmTestSpProbe probe{0, &probe_ctx.sp, &back};
        // Deliberately misaligned stack tops: the port must realign.
        auto* lo = static_cast<unsigned char*>(stack.lo()) + 16;
        chm::port::context_init(&probe_ctx, lo, 16 * 1024 - offset, chm_test_sp_probe_entry, &probe);
        chm_port_switch(&back, probe_ctx.sp);
        ASSERT_NE(probe.sp_at_entry, 0u);
        EXPECT_EQ((probe.sp_at_entry + chm::port::kSpAtEntryBias) % chm::port::kStackAlign, 0u)
            << "sp at entry 0x" << std::hex << probe.sp_at_entry << " with top offset " << offset;
        // The whole frame lies inside the stack.
        EXPECT_GT(probe.sp_at_entry, reinterpret_cast<std::uintptr_t>(lo));
        EXPECT_LE(probe.sp_at_entry, reinterpret_cast<std::uintptr_t>(lo) + 16 * 1024 - offset);
    }
}

// ---- a fresh context starts with the ABI's default FP control state
Context g_fp_main, g_fp_ctx;
int g_fp_round_seen = -1;
volatile double g_fp_a = 1.0, g_fp_b = 3.0;
double g_fp_quotient = 0;

void fp_entry(void*) {
    g_fp_round_seen = std::fegetround();
    g_fp_quotient = g_fp_a / g_fp_b;
    chm::port::context_switch(&g_fp_ctx, &g_fp_main);
    std::abort();
}

TEST(PortSwitch, NewContextStartsWithDefaultFpControl) {
    Stack stack(32 * 1024);
    chm::port::context_init(&g_fp_ctx, stack.lo(), stack.size(), fp_entry, nullptr);
    ASSERT_EQ(std::fesetround(FE_UPWARD), 0);
    chm::port::context_switch(&g_fp_main, &g_fp_ctx);
    const int mine = std::fegetround();
    std::fesetround(FE_TONEAREST);
    EXPECT_EQ(g_fp_round_seen, FE_TONEAREST);
    EXPECT_EQ(mine, FE_UPWARD) << "the switch back must restore the saver's rounding mode";
    // Through a volatile so m68k's 80-bit registers do not leak precision.
    volatile double q = g_fp_quotient;
    EXPECT_NEAR(q, 1.0 / 3.0, 1e-15);
}

}  // namespace
