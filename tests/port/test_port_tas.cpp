// Port conformance: test-and-set gives mutual exclusion between real threads.
#include <gtest/gtest.h>

#include <cstdint>
#include <thread>
#include <vector>

#include "port.hpp"

namespace {

TEST(PortTas, SetReportsPreviousState) {
    volatile std::uint8_t b = 0;
    EXPECT_TRUE(chm::port::tas(&b));
    EXPECT_FALSE(chm::port::tas(&b));
    chm::port::tas_clear(&b);
    EXPECT_TRUE(chm::port::tas(&b));
}

TEST(PortTas, MutualExclusionBetweenThreadsLosesNoIncrement) {
    constexpr int kThreads = 4;
    constexpr long kPerThread = 500000;  // 2 million increments in all
    alignas(64) static volatile std::uint8_t lock = 0;
    // Plain (non-atomic) read-modify-write: only the lock protects it.
    alignas(64) static volatile long counter = 0;
    counter = 0;
    std::vector<std::thread> threads;
    for (int t = 0; t < kThreads; ++t) {
        threads.emplace_back([] {
            for (long i = 0; i < kPerThread; ++i) {
                while (!chm::port::tas(&lock)) chm::port::relax();
                counter = counter + 1;
                chm::port::tas_clear(&lock);
            }
        });
    }
    for (auto& th : threads) th.join();
    EXPECT_EQ(counter, kThreads * kPerThread);
    EXPECT_EQ(lock, 0);
}

}  // namespace
