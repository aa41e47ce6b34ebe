// Task ids never repeat: a stale id never names a task spawned later on
// its slot, however often the slot is reused (chm_tid_t, chimera/task.h).
#include <cerrno>
#include <set>
#include <vector>

#include "kernel.hpp"
#include "kernel_fixture.hpp"

namespace chm::test {
namespace {

class TaskIds : public KernelTest {};

// Well past the 32,767 spawns after which a 32-bit id's 15-bit generation
// came round to the first id of the slot again.
constexpr int kChurn = 100'000;

void nop(void*) {}

chm_tid_t spawn_named(const char* name) {
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = name;
    chm_tid_t id = CHM_TID_NONE;
    EXPECT_EQ(chm_task_spawn(&id, nop, nullptr, &a), 0);
    return id;
}

std::vector<chm_tid_t> g_stale;  // a sample of the ended ids, oldest first
int g_failures = 0;

// Spawns and destroys kChurn tasks on one slot; after each spawn the
// first id of the slot, and one in every 1,000 since, must still be stale.
void churn(void*) {
    const chm_tid_t first = spawn_named("first");
    ASSERT_EQ(chm_task_destroy(first), 0);
    g_stale.push_back(first);
    std::set<chm_tid_t> seen{first};
    for (int n = 1; n <= kChurn && g_failures < 5; ++n) {
        const chm_tid_t id = spawn_named("new");
        if ((id & 0xffff) != (first & 0xffff)) {
            ADD_FAILURE() << "spawn " << n << " took slot " << (id & 0xffff) << ", not the churned slot";
            return;
        }
        if (!seen.insert(id).second) {
            ADD_FAILURE() << "spawn " << n << " repeated id " << id;
            ++g_failures;
        }
        chm_task_status_t st;
        if (chm_task_status(first, &st) != -ESRCH) {
            ADD_FAILURE() << "after " << n << " spawns the first id " << first << " names a task (\"" << st.name
                          << "\", id " << st.id << ")";
            ++g_failures;
        }
        if (n % 1000 == 0) g_stale.push_back(id);
        ASSERT_EQ(chm_task_destroy(id), 0);
    }
    // The live task now on the slot is not reached through any old id.
    const chm_tid_t live = spawn_named("live");
    for (chm_tid_t old : g_stale) {
        EXPECT_EQ(chm_task_destroy(old), -ESRCH) << "stale id " << old;
        EXPECT_EQ(chm_task_suspend(old), -ESRCH) << "stale id " << old;
    }
    chm_task_status_t st;
    ASSERT_EQ(chm_task_status(live, &st), 0);
    EXPECT_STREQ(st.name, "live");
    EXPECT_EQ(st.state, CHM_TASK_READY) << "untouched by the calls on stale ids";
    EXPECT_GT(uint64_t(live) >> 16, uint64_t(kChurn)) << "the generation counts on past 15 bits";
    // The 31-bit form shared memory carries: the old id for a slot's first
    // 32,767 generations, folded into 1..0x7fff after, cached in the TCB.
    EXPECT_EQ(kernel::tid_short(first), std::uint32_t(first));
    const std::uint32_t s = kernel::tid_short(live);
    EXPECT_EQ(s & 0xffff, std::uint32_t(live & 0xffff));
    EXPECT_GE(s >> 16, 1u);
    EXPECT_LE(s >> 16, 0x7fffu);
    EXPECT_EQ(kernel::tid_short(&kernel::g_k.tcbs[live & 0xffff]), s);
}

TEST_F(TaskIds, AStaleIdNeverNamesALaterTaskOfItsSlot) {
    start(CHM_SCHED_FIXED);
    g_stale.clear();
    g_failures = 0;
    spawn(churn, nullptr, "churn", 5);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_failures, 0);
    EXPECT_EQ(g_stale.size(), std::size_t(kChurn / 1000 + 1));
}

chm_tid_t g_last = CHM_TID_NONE, g_next = CHM_TID_NONE;

// Brings the churned slot to its last generation, ends the task that has
// it, and spawns again: the slot is retired, the next task takes another.
void retire(void*) {
    const chm_tid_t a = spawn_named("a");
    ASSERT_EQ(chm_task_destroy(a), 0);
    const std::uint32_t slot = std::uint32_t(a & 0xffff);
    {
        kernel::IrqGuard guard;
        kernel::g_k.tcbs[slot].gen = kernel::kGenMax - 1;  // as after 2^47 - 2 spawns
    }
    g_last = spawn_named("last");
    ASSERT_EQ(std::uint32_t(g_last & 0xffff), slot);
    EXPECT_EQ(std::uint64_t(g_last) >> 16, kernel::kGenMax);
    EXPECT_GT(g_last, 0) << "the last generation still gives a positive id";
    ASSERT_EQ(chm_task_destroy(g_last), 0);
    EXPECT_EQ(kernel::g_k.slots_retired, 1u);
    g_next = spawn_named("next");
    EXPECT_NE(std::uint32_t(g_next & 0xffff), slot) << "a retired slot is never taken again";
    chm_task_status_t st;
    EXPECT_EQ(chm_task_status(a, &st), -ESRCH);
    EXPECT_EQ(chm_task_destroy(g_next), 0);
}

TEST_F(TaskIds, ASlotThatUsedItsLastGenerationIsRetired) {
    start(CHM_SCHED_FIXED);
    spawn(retire, nullptr, "retire", 5);
    ASSERT_EQ(chm_kernel_run(), 0);
    ASSERT_NE(g_last, CHM_TID_NONE);
    const std::uint32_t slot = std::uint32_t(g_last & 0xffff);
    // A new kernel in the same process keeps the slot retired.
    chm_kernel_fini();
    started_ = false;
    start(CHM_SCHED_FIXED);
    EXPECT_EQ(kernel::g_k.slots_retired, 1u);
    for (int i = 0; i < 8; ++i) {
        const chm_tid_t id = spawn_named("after");
        EXPECT_NE(std::uint32_t(id & 0xffff), slot);
    }
}

}  // namespace
}  // namespace chm::test
