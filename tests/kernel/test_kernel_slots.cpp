// Which task slot a spawn takes (task/task.cpp, slot_release_locked),
// against a model written from the rule as a user reads it, not from the
// kernel's two lists: the free slots in the order they were freed; a spawn
// takes the (K+1)-th most recently freed when more than K are free (K =
// kSlotRetain: an ended task's status stays readable through K later
// ends), else the least recently freed, else a slot never used. Random
// spawns, destroys and tasks that run and end, through the public API.
#include <algorithm>
#include <cinttypes>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "kernel/kernel.hpp"
#include "kernel_fixture.hpp"

namespace chm::test {
namespace {

struct SlotModel {
    std::vector<std::uint32_t> free;  // least recently freed first
    std::uint32_t hw = 0;             // slots ever used
    int over = 0;                     // takes with more than K free
    std::uint32_t take() {
        const std::size_t n = free.size(), k = kernel::kSlotRetain;
        if (n == 0) return hw++;
        const std::size_t at = n > k ? n - 1 - k : 0;
        if (n > k) ++over;
        const std::uint32_t s = free[at];
        free.erase(free.begin() + std::ptrdiff_t(at));
        return s;
    }
    void release(std::uint32_t s) { free.push_back(s); }
};

std::uint32_t slot_of(chm_tid_t id) { return std::uint32_t(id) & 0xffff; }

struct SlotRun {
    SlotModel model;
    std::mt19937_64 rng;
    int ops = 0;
    std::string failure;  // the first disagreement, with the ops before it
    std::vector<std::string> log;
};

void nop(void*) {}

void check(SlotRun& r, const char* what, chm_tid_t id, std::uint32_t want) {
    std::ostringstream line;
    line << what << " -> slot " << slot_of(id) << " (model " << want << ", " << r.model.free.size() << " free)";
    r.log.push_back(line.str());
    if (r.failure.empty() && slot_of(id) != want) {
        std::ostringstream f;
        f << "op " << r.log.size() << ": " << line.str() << "\nlast ops:";
        for (std::size_t i = r.log.size() > 12 ? r.log.size() - 12 : 0; i < r.log.size(); ++i) f << "\n  " << r.log[i];
        r.failure = f.str();
    }
}

// The driver (priority 5): spawns tasks below it that wait (priority 1),
// destroys them, and spawns tasks above it that run and end at once. The
// number of waiting tasks heads for a target between 0 and 3 K that
// changes every 300 operations, so the free slots go above and below K
// (with a walk that stayed near its cap they never passed K, and the
// test passed against the old oldest-freed-first rule).
void driver(void* p) {
    SlotRun& r = *static_cast<SlotRun*>(p);
    std::vector<chm_tid_t> waiting;
    chm_task_attr_t low, high;
    chm_task_attr_init(&low);
    chm_task_attr_init(&high);
    low.priority = 1;
    high.priority = 9;
    low.stack_size = high.stack_size = 16 * 1024;
    std::size_t target = 0;  // waiting tasks the walk heads for, changed every 300 ops
    for (int op = 0; op < r.ops && r.failure.empty(); ++op) {
        if (op % 300 == 0) target = std::size_t(r.rng() % (3 * kernel::kSlotRetain + 1));
        const std::uint64_t dice = r.rng() % 100;
        const bool grow = waiting.size() < target ? dice < 70 : waiting.empty() || dice < 20;
        if (grow) {
            chm_tid_t id = CHM_TID_NONE;
            ASSERT_EQ(chm_task_spawn(&id, nop, nullptr, &low), 0);
            check(r, "spawn waiting", id, r.model.take());
            waiting.push_back(id);
        } else if (dice < 90 && !waiting.empty()) {
            const std::size_t i = std::size_t(r.rng() % waiting.size());
            ASSERT_EQ(chm_task_destroy(waiting[i]), 0);
            r.log.push_back("destroy slot " + std::to_string(slot_of(waiting[i])));
            r.model.release(slot_of(waiting[i]));
            waiting.erase(waiting.begin() + std::ptrdiff_t(i));
        } else {
            chm_tid_t id = CHM_TID_NONE;
            ASSERT_EQ(chm_task_spawn(&id, nop, nullptr, &high), 0);  // it ran and ended: its slot is free again
            const std::uint32_t want = r.model.take();
            check(r, "spawn, run, end", id, want);
            r.model.release(want);
        }
    }
    for (chm_tid_t id : waiting) ASSERT_EQ(chm_task_destroy(id), 0);
}

class Slots : public KernelTest {};

TEST_F(Slots, ASpawnTakesTheSlotTheRuleNames) {
    std::uint64_t seed = env_or("CHM_SLOTS_SEED", 20261127);
    if (!seed) seed = std::random_device{}() | 1;
    std::printf("seed %" PRIu64 " (CHM_SLOTS_SEED)\n", seed);
    start(CHM_SCHED_FIXED);
    SlotRun r;
    r.rng.seed(seed);
    r.ops = int(env_or("CHM_SLOTS_OPS", 20000));
    // A new kernel finds every slot the last one used free, released in
    // slot order (chm_kernel_fini).
    r.model.hw = kernel::g_k.tcb_hw;
    for (std::uint32_t s = 0; s < r.model.hw; ++s) r.model.release(s);
    const chm_tid_t d = spawn(driver, &r, "driver", 5);
    check(r, "spawn driver", d, r.model.take());
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(r.failure, "") << "seed " << seed;
    EXPECT_GT(r.model.over, r.ops / 10) << "the walk seldom had more than K slots free";
}

// What the rule is for. An ended task stays readable through K later
// ends while more than K slots are free; and after a burst of tasks has
// ended, tasks spawned and ended in turn reuse K + 1 slots, not every
// slot of the burst (their TCBs stay in the cache).
void burst_then_churn(void* p) {
    auto* seen = static_cast<std::vector<std::uint32_t>*>(p);
    chm_task_attr_t low, high;
    chm_task_attr_init(&low);
    chm_task_attr_init(&high);
    low.priority = 1;
    high.priority = 9;
    std::vector<chm_tid_t> burst(1000);
    for (auto& id : burst) ASSERT_EQ(chm_task_spawn(&id, nop, nullptr, &low), 0);
    for (chm_tid_t id : burst) ASSERT_EQ(chm_task_destroy(id), 0);
    chm_tid_t first = CHM_TID_NONE;
    ASSERT_EQ(chm_task_spawn(&first, nop, nullptr, &high), 0);  // ran and ended
    chm_task_status_t st;
    for (std::uint32_t i = 0; i < 10 * kernel::kSlotRetain; ++i) {
        if (i < kernel::kSlotRetain) {
            EXPECT_EQ(chm_task_status(first, &st), 0) << "after " << i << " later ends";
        }
        chm_tid_t id = CHM_TID_NONE;
        ASSERT_EQ(chm_task_spawn(&id, nop, nullptr, &high), 0);
        if (i >= 2 * kernel::kSlotRetain) seen->push_back(slot_of(id));
    }
}

TEST_F(Slots, EndedTasksStayReadableAndChurnReusesFewSlots) {
    start(CHM_SCHED_FIXED);
    std::vector<std::uint32_t> seen;
    spawn(burst_then_churn, &seen, "churn", 5);
    ASSERT_EQ(chm_kernel_run(), 0);
    std::sort(seen.begin(), seen.end());
    seen.erase(std::unique(seen.begin(), seen.end()), seen.end());
    EXPECT_LE(seen.size(), std::size_t(kernel::kSlotRetain + 1)) << "distinct slots in the churn";
}

}  // namespace
}  // namespace chm::test
