// Tasks on the virtual clock: lifecycle, round robin, suspend/resume,
// priorities, lookup, status and the bad-input rules.
#include <cerrno>
#include <cstring>

#include "kernel_fixture.hpp"

namespace chm::test {
namespace {

std::vector<Event> g_trace;

void note(const char* who) { g_trace.push_back({chm_time_now(), who}); }

class Tasks : public KernelTest {
protected:
    void SetUp() override { g_trace.clear(); }
};

void say_and_end(void* name) { note(static_cast<const char*>(name)); }

TEST_F(Tasks, MoreUrgentFirstThenRunEndsWhenAllTasksEnd) {
    start(CHM_SCHED_FIXED);
    spawn(say_and_end, (void*)"low", "low", 1);
    spawn(say_and_end, (void*)"high", "high", 5);
    spawn(say_and_end, (void*)"mid", "mid", 3);
    EXPECT_EQ(chm_task_count(), 3);
    EXPECT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(chm_task_count(), 0);
    std::vector<Event> want{{0, "high"}, {0, "mid"}, {0, "low"}};
    EXPECT_EQ(g_trace, want);
}

void yielder(void* name) {
    for (int i = 0; i < 3; ++i) {
        note(static_cast<const char*>(name));
        chm_task_yield();
    }
}

TEST_F(Tasks, YieldRotatesAmongEquals) {
    start(CHM_SCHED_FIXED);
    spawn(yielder, (void*)"a", "a", 2);
    spawn(yielder, (void*)"b", "b", 2);
    spawn(yielder, (void*)"c", "c", 2);
    ASSERT_EQ(chm_kernel_run(), 0);
    std::string order;
    for (auto& e : g_trace) order += e.who;
    EXPECT_EQ(order, "abcabcabc");
}

void worker_1ms_x5(void* name) {
    for (int i = 0; i < 5; ++i) {
        // Noted once it ran (stamped with its start): a task's code runs on
        // to its next kernel call before the events of the instant its
        // work ended are acted on.
        chm_time_consume(kMs);
        g_trace.push_back({chm_time_now() - kMs, static_cast<const char*>(name)});
    }
}

TEST_F(Tasks, QuantumSharesTheCpuRoundRobinOnTheVirtualClock) {
    start(CHM_SCHED_FIXED, true, 2 * kMs);
    spawn(worker_1ms_x5, (void*)"a", "a", 1);
    spawn(worker_1ms_x5, (void*)"b", "b", 1);
    ASSERT_EQ(chm_kernel_run(), 0);
    std::vector<Event> want{{0, "a"}, {1 * kMs, "a"}, {2 * kMs, "b"}, {3 * kMs, "b"},
                            {4 * kMs, "a"}, {5 * kMs, "a"}, {6 * kMs, "b"}, {7 * kMs, "b"},
                            {8 * kMs, "a"}, {9 * kMs, "b"}};
    EXPECT_EQ(g_trace, want);
}

chm_tid_t g_victim;
void victim(void*) {
    for (int i = 0; i < 4; ++i) {
        note("victim");
        chm_time_consume(kMs);
    }
}
void controller(void*) {
    chm_time_consume(kMs);  // victim is lower: it has not run yet
    note("suspend");
    EXPECT_EQ(chm_task_suspend(g_victim), 0);
    EXPECT_EQ(chm_task_pause_until(5 * kMs), 0);
    chm_task_status_t st;
    ASSERT_EQ(chm_task_status(g_victim, &st), 0);
    EXPECT_EQ(st.state, CHM_TASK_SUSPENDED);
    note("resume");
    EXPECT_EQ(chm_task_resume(g_victim), 0);
    EXPECT_EQ(chm_task_resume(g_victim), -EINVAL);
}

TEST_F(Tasks, SuspendedTaskDoesNotRunUntilResumed) {
    start(CHM_SCHED_FIXED);
    g_victim = spawn(victim, nullptr, "victim", 1);
    spawn(controller, nullptr, "controller", 9);
    ASSERT_EQ(chm_kernel_run(), 0);
    std::vector<Event> want{{1 * kMs, "suspend"}, {5 * kMs, "resume"}, {5 * kMs, "victim"},
                            {6 * kMs, "victim"}, {7 * kMs, "victim"}, {8 * kMs, "victim"}};
    EXPECT_EQ(g_trace, want);
}

chm_tid_t g_a, g_b;
void raiser(void*) {
    note("raiser");
    EXPECT_EQ(chm_task_set_priority(g_b, 10), 0);  // b now preempts us
    note("raiser-after");
}
void plain(void* name) { note(static_cast<const char*>(name)); }

TEST_F(Tasks, RaisingAPriorityPreemptsAtOnce) {
    start(CHM_SCHED_FIXED);
    g_a = spawn(raiser, nullptr, "raiser", 5);
    g_b = spawn(plain, (void*)"b", "b", 1);
    ASSERT_EQ(chm_kernel_run(), 0);
    std::string order;
    for (auto& e : g_trace) order += e.who + " ";
    EXPECT_EQ(order, "raiser b raiser-after ");
}

void finder(void*) {
    chm_tid_t me = chm_task_self(), found;
    ASSERT_EQ(chm_task_find("finder", &found), 0);
    EXPECT_EQ(found, me);
    EXPECT_EQ(chm_task_find("nobody", &found), -ESRCH);
    char big[4096];
    std::memset(big, 1, sizeof big);  // dirties at least 4 KiB of stack
    asm volatile("" : : "r"(big) : "memory");
    chm_time_consume(3 * kMs);
    chm_task_status_t st;
    ASSERT_EQ(chm_task_status(me, &st), 0);
    EXPECT_STREQ(st.name, "finder");
    EXPECT_EQ(st.state, CHM_TASK_RUNNING);
    EXPECT_EQ(st.cpu_ns, 3 * kMs);
    EXPECT_GE(st.stack_high_water, 4096u);
    EXPECT_LT(st.stack_high_water, st.stack_size);
}

void nop_task(void*) {}

// Spawns tasks (left ready) until `id` no longer reads; returns the last one.
chm_tid_t spawn_until_stale(chm_tid_t id) {
    chm_task_status_t st;
    chm_tid_t last = CHM_TID_NONE;
    for (int n = 0; n < 1000 && chm_task_status(id, &st) == 0; ++n) {
        chm_task_attr_t a;
        chm_task_attr_init(&a);
        a.name = "filler";
        EXPECT_EQ(chm_task_spawn(&last, nop_task, nullptr, &a), 0);
    }
    EXPECT_NE(chm_task_status(id, &st), 0);
    return last;
}

TEST_F(Tasks, FindByNameAndStatusSnapshot) {
    start(CHM_SCHED_MUF);
    chm_tid_t id = spawn(finder, nullptr, "finder");
    ASSERT_EQ(chm_kernel_run(), 0);
    chm_task_status_t st;
    ASSERT_EQ(chm_task_status(id, &st), 0) << "an ended task's final counters stay readable";
    EXPECT_EQ(st.state, CHM_TASK_ENDED);
    EXPECT_STREQ(st.name, "finder");
    EXPECT_EQ(st.cpu_ns, 3 * kMs);
    EXPECT_GE(st.stack_high_water, 4096u);
    // Until its slot is taken by a new task: then the id is stale.
    const chm_tid_t last = spawn_until_stale(id);
    EXPECT_EQ(last & 0xffff, id & 0xffff) << "stale exactly when its slot was reused";
}

// A pooled stack goes to its next task scrubbed: that task's high water is
// its own, not the deep one's that ran there before (stack.cpp re-zeroes
// what a task dirtied as it releases the stack, and the high water reads
// zero as "never touched"). The stack size is one only these tasks use.
constexpr std::size_t kScrubStack = 48 * 1024;
std::size_t g_shallow_high_water = 0;

__attribute__((noinline)) void dirty_deep(std::size_t n) {
    volatile unsigned char buf[32 * 1024];
    for (std::size_t i = 0; i < n && i < sizeof buf; i += 64) buf[i] = 1;
}
std::size_t g_deep_high_water = 0;
void deep_task(void*) { dirty_deep(32 * 1024); }
void shallow_task(void*) {
    chm_task_status_t st;
    ASSERT_EQ(chm_task_status(chm_task_self(), &st), 0);
    g_shallow_high_water = st.stack_high_water;
}
// Spawns the deep task (more urgent: it runs and ends at once), then the
// shallow one, on a stack of the same size: the deep one's, back from the pool.
void deep_then_shallow(void*) {
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.stack_size = kScrubStack;
    a.priority = 5;
    chm_tid_t deep, shallow;
    ASSERT_EQ(chm_task_spawn(&deep, deep_task, nullptr, &a), 0);
    chm_task_status_t st;
    ASSERT_EQ(chm_task_status(deep, &st), 0);
    g_deep_high_water = st.stack_high_water;
    ASSERT_EQ(chm_task_spawn(&shallow, shallow_task, nullptr, &a), 0);
}

TEST_F(Tasks, APooledStackComesScrubbedToItsNextTask) {
    start(CHM_SCHED_FIXED);
    spawn(deep_then_shallow, nullptr, "driver", 1);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_GE(g_deep_high_water, 32u * 1024) << "the deep task's own use is measured";
    EXPECT_GT(g_shallow_high_water, 0u);
    EXPECT_LT(g_shallow_high_water, 16u * 1024) << "the deep task's bytes were left on the reused stack";
}

// With few slots free, the least recently freed is taken first
// (test_kernel_slots.cpp has the whole rule): of two ended tasks, the one
// that ended last stays readable longer.
TEST_F(Tasks, EndedTasksStayReadableUntilTheirSlotIsReused) {
    start(CHM_SCHED_MUF);
    chm_tid_t a = spawn(nop_task, nullptr, "a"), b = spawn(nop_task, nullptr, "b");
    ASSERT_EQ(chm_kernel_run(), 0);  // a ends first
    spawn_until_stale(a);
    chm_task_status_t st;
    ASSERT_EQ(chm_task_status(b, &st), 0);
    EXPECT_STREQ(st.name, "b");
    EXPECT_EQ(st.state, CHM_TASK_ENDED);
}

// A spawn leaves the rarely used parts of a recycled TCB as the last task
// left them (kernel.hpp): a new task in the same slot must still start
// with no signal handlers and a clean name.
int g_handler_runs = 0;
chm_tid_t g_first = CHM_TID_NONE, g_second = CHM_TID_NONE;
void count_handler(int, void*) { ++g_handler_runs; }
void installs_handler_and_ends(void*) { EXPECT_EQ(chm_usig_handle(3, count_handler, nullptr), 0); }
void quiet(void*) {}
void spawns_into_the_freed_slot(void*) {
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = "b";
    a.priority = 0;  // below us: it runs once we end, with signal 3 pending
    // Other free slots go by (each spawned and destroyed, freed again)
    // until the first task's slot comes up (test_kernel_slots.cpp has the
    // order).
    for (int i = 0; i < 40000; ++i) {
        ASSERT_EQ(chm_task_spawn(&g_second, quiet, nullptr, &a), 0);
        if ((g_second & 0xffff) == (g_first & 0xffff)) break;
        ASSERT_EQ(chm_task_destroy(g_second), 0);
    }
    ASSERT_EQ(g_second & 0xffff, g_first & 0xffff) << "the first task's slot, taken again";
    EXPECT_EQ(chm_usig_send(g_second, 3), 0);
}

TEST_F(Tasks, ARecycledSlotKeepsNoSignalHandlerAndNoNameOfItsLastTask) {
    start(CHM_SCHED_FIXED);
    g_handler_runs = 0;
    g_first = spawn(installs_handler_and_ends, nullptr, "a-longer-name-of-29-characters", 5);
    spawn(spawns_into_the_freed_slot, nullptr, "spawner", 1);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_handler_runs, 0) << "the slot's last task's handler ran for the new task";
    chm_task_status_t st;
    ASSERT_EQ(chm_task_status(g_second, &st), 0);
    EXPECT_STREQ(st.name, "b");
    for (std::size_t i = 1; i < sizeof st.name; ++i) EXPECT_EQ(st.name[i], 0) << "byte " << i;
}

// The scheduler's view of a new task starts clean in a recycled slot: a
// user scheduler (MUF's operations, wrapped) leaves its scratch fields
// set when a task is retired, and finds them zero when the next task in
// that slot is admitted.
int g_dirty_admits = 0, g_admits = 0;
int wrap_admit(void* self, chm_sched_task_t* t) {
    ++g_admits;
    if (t->key || t->data || t->cycle_cpu_ns || t->release_ns) ++g_dirty_admits;
    return chm_sched_muf_ops.admit(self, t);
}
void wrap_retire(void* self, chm_sched_task_t* t) {
    chm_sched_muf_ops.retire(self, t);
    t->key = 0xdead;
    t->data = &g_dirty_admits;
}

TEST_F(Tasks, ARecycledSlotStartsWithACleanSchedulerView) {
    chm_sched_ops_t ops = chm_sched_muf_ops;
    ops.name = "muf-wrapped";
    ops.admit = wrap_admit;
    ops.retire = wrap_retire;
    start(CHM_SCHED_USER, true, 0, &ops);
    g_dirty_admits = g_admits = 0;
    const chm_tid_t first = spawn(quiet, nullptr, "first", 1);
    ASSERT_EQ(chm_task_destroy(first), 0);
    chm_tid_t id = CHM_TID_NONE;
    for (int i = 0; i < 40000; ++i) {  // until its slot comes up
        id = spawn(quiet, nullptr, "next", 1);
        if ((id & 0xffff) == (first & 0xffff)) break;
        ASSERT_EQ(chm_task_destroy(id), 0);
    }
    ASSERT_EQ(id & 0xffff, first & 0xffff);
    EXPECT_GE(g_admits, 2);
    EXPECT_EQ(g_dirty_admits, 0) << "a view admitted with its slot's last task's scratch fields";
    EXPECT_EQ(chm_kernel_run(), 0);
}

// A task locked into the CPU runs late through two deadlines; its handler
// runs once, when it unlocks, and is told both.
std::vector<chm_deadline_info_t> g_dl_calls;
chm_deadline_action record_miss(const chm_deadline_info_t* info, void*) {
    g_dl_calls.push_back(*info);
    return CHM_DL_CONTINUE;
}
void late_while_locked(void*) {
    chm_task_lock();
    chm_time_consume(25 * kMs);  // cycle 0 (deadline 10 ms) ends at 25 ms
    EXPECT_EQ(chm_task_wait_period(), 0);  // cycle 1 is due (10 ms), its deadline passed (20 ms)
    chm_time_consume(kMs);
    EXPECT_TRUE(g_dl_calls.empty()) << "locked: nothing runs on its behalf yet";
    chm_task_unlock();
}

TEST_F(Tasks, ADeadlineHandlerIsToldHowManyDeadlinesPassedBeforeItRan) {
    start(CHM_SCHED_MUF);
    g_dl_calls.clear();
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = "late";
    a.period_ns = 10 * kMs;
    a.on_deadline = record_miss;
    ASSERT_EQ(chm_task_spawn(nullptr, late_while_locked, nullptr, &a), 0);
    ASSERT_EQ(chm_kernel_run(), 0);
    ASSERT_EQ(g_dl_calls.size(), 1u);
    EXPECT_EQ(g_dl_calls[0].unhandled, 2u);
    EXPECT_EQ(g_dl_calls[0].misses, 2u);
    EXPECT_EQ(g_dl_calls[0].cycle, 1u) << "the latest miss";
    EXPECT_EQ(g_dl_calls[0].deadline_ns, 20 * kMs);
}

void nop(void*) {}

TEST_F(Tasks, BadAttributesAreRefusedAndLeaveNothingBehind) {
    start(CHM_SCHED_MUF);
    chm_task_attr_t a;
    chm_tid_t id;
    chm_task_attr_init(&a);
    EXPECT_EQ(chm_task_spawn(&id, nullptr, nullptr, &a), -EINVAL);
    a.stack_size = 1024;
    EXPECT_EQ(chm_task_spawn(&id, nop, nullptr, &a), -EINVAL) << "stack too small";
    chm_task_attr_init(&a);
    a.period_ns = 10 * kMs;
    a.deadline_ns = 20 * kMs;
    EXPECT_EQ(chm_task_spawn(&id, nop, nullptr, &a), -EINVAL) << "deadline beyond period";
    chm_task_attr_init(&a);
    a.period_ns = 10 * kMs;
    a.wcet_ns = 11 * kMs;
    EXPECT_EQ(chm_task_spawn(&id, nop, nullptr, &a), -EINVAL) << "wcet beyond deadline";
    chm_task_attr_init(&a);
    a.deadline_ns = 5 * kMs;
    EXPECT_EQ(chm_task_spawn(&id, nop, nullptr, &a), -EINVAL) << "deadline without a period";
    chm_task_attr_init(&a);
    a.name = "a-name-that-is-far-too-long-for-a-task-name";
    EXPECT_EQ(chm_task_spawn(&id, nop, nullptr, &a), -ENAMETOOLONG);
    EXPECT_EQ(chm_task_count(), 0);
    EXPECT_EQ(chm_task_destroy(12345), -ESRCH);
    EXPECT_EQ(chm_task_suspend(-7), -ESRCH);
    EXPECT_EQ(chm_task_set_priority(99, 1), -ESRCH);
    EXPECT_EQ(chm_kernel_run(), 0);
}

TEST(KernelInit, SchedulerTableWithMissingOperationsIsRefused) {
    chm_sched_ops_t ops{};
    ops.name = "half";
    chm_kernel_config_t cfg;
    chm_kernel_config_init(&cfg);
    cfg.policy = CHM_SCHED_USER;
    cfg.user_sched = &ops;
    cfg.virtual_clock = 1;
    EXPECT_EQ(chm_kernel_init(&cfg), -EINVAL);
    cfg.policy = CHM_SCHED_MUF;
    cfg.quantum_ns = 5;  // below 10 µs
    EXPECT_EQ(chm_kernel_init(&cfg), -EINVAL);
    EXPECT_EQ(chm_task_spawn(nullptr, nop, nullptr, nullptr), -EPERM) << "not initialised";
}

void spawner(void*) {
    for (int i = 0; i < 1000; ++i) {
        chm_tid_t id;
        ASSERT_EQ(chm_task_spawn(&id, nop, nullptr, nullptr), 0);
        ASSERT_EQ(chm_task_destroy(id), 0);
    }
}

TEST_F(Tasks, SpawnDestroyCyclesReuseSlotsAndStacks) {
    start(CHM_SCHED_FIXED);
    spawn(spawner, nullptr, "spawner", 5);
    ASSERT_EQ(chm_kernel_run(), 0);
}

}  // namespace
}  // namespace chm::test
