// A task's life after spawn, on the virtual clock: joining it and its exit
// status, end hooks and task-local values whichever way it ends, and a
// timing change that takes effect at the next release.
#include <cerrno>
#include <string>
#include <vector>

#include "kernel_fixture.hpp"

namespace chm::test {
namespace {

class Lifecycle : public KernelTest {};

std::vector<std::string> g_log;
chm_tid_t spawn_joinable(void (*fn)(void*), void* arg, const char* name, int prio = 0) {
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = name;
    a.priority = prio;
    a.joinable = 1;
    chm_tid_t id = CHM_TID_NONE;
    EXPECT_EQ(chm_task_spawn(&id, fn, arg, &a), 0);
    return id;
}

void returns(void*) { chm_time_consume(kMs); }
void ends_with_7(void*) {
    chm_time_consume(kMs);
    chm_task_end(7);
}
void aborts(void*) {
    chm_time_consume(kMs);
    chm_err_invoke(CHM_ERR_KERNEL, CHM_EK_CANARY);  // the default handler aborts the task
    g_log.push_back("not reached");
}
void forever(void*) {
    for (;;) chm_time_consume(kMs);
}

struct JoinCase {
    void (*body)(void*);
    chm_task_end_reason reason;
    int status;
};

void joiner(void*) {
    const JoinCase cases[] = {{returns, CHM_TASK_RETURNED, 0},
                              {ends_with_7, CHM_TASK_EXITED, 7},
                              {aborts, CHM_TASK_ABORTED, 0}};
    for (const JoinCase& c : cases) {
        const chm_tid_t id = spawn_joinable(c.body, nullptr, "child");
        chm_task_status_t st{};
        ASSERT_EQ(chm_task_join(id, CHM_FOREVER, &st), 0);
        EXPECT_EQ(st.end_reason, c.reason);
        EXPECT_EQ(st.exit_status, c.status);
        EXPECT_EQ(st.state, CHM_TASK_ENDED);
        EXPECT_EQ(st.cpu_ns, kMs);
        EXPECT_EQ(chm_task_status(id, &st), -ESRCH) << "joined: the slot is free";
        EXPECT_EQ(chm_task_join(id, CHM_FOREVER, &st), -ESRCH);
    }
    // Destroyed while it runs on, with a bounded join first.
    const chm_tid_t id = spawn_joinable(forever, nullptr, "forever", -1);
    const std::uint64_t t0 = chm_time_now();
    EXPECT_EQ(chm_task_join(id, 3 * kMs, nullptr), -ETIMEDOUT);
    EXPECT_EQ(chm_time_now() - t0, 3 * kMs) << "the timeout is exact on the virtual clock";
    EXPECT_EQ(chm_task_join(id, CHM_NO_WAIT, nullptr), -EAGAIN);
    ASSERT_EQ(chm_task_destroy(id), 0);
    chm_task_status_t st{};
    ASSERT_EQ(chm_task_join(id, CHM_NO_WAIT, &st), 0) << "ended: no wait needed";
    EXPECT_EQ(st.end_reason, CHM_TASK_DESTROYED);
    // Refusals.
    EXPECT_EQ(chm_task_join(chm_task_self(), CHM_FOREVER, nullptr), -EINVAL) << "main is not joinable";
    chm_tid_t plain;
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.priority = -1;
    ASSERT_EQ(chm_task_spawn(&plain, returns, nullptr, &a), 0);
    EXPECT_EQ(chm_task_join(plain, CHM_FOREVER, nullptr), -EINVAL);
    g_log.push_back("joiner done");
}

TEST_F(Lifecycle, JoinGivesHowATaskEndedAndItsStatusThenFreesItsSlot) {
    start(CHM_SCHED_FIXED);
    g_log.clear();
    spawn(joiner, nullptr, "joiner", 1);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_log, (std::vector<std::string>{"joiner done"}));
}

chm_tid_t g_target;
void waits_on_itself(void*) { EXPECT_EQ(chm_task_join(chm_task_self(), CHM_FOREVER, nullptr), -EDEADLK); }
void first_joiner(void*) { EXPECT_EQ(chm_task_join(g_target, CHM_FOREVER, nullptr), 0); }
void second_joiner(void*) { EXPECT_EQ(chm_task_join(g_target, CHM_FOREVER, nullptr), -EBUSY); }

TEST_F(Lifecycle, OneJoinerAtATimeAndNeverItself) {
    start(CHM_SCHED_FIXED);
    g_target = spawn_joinable(returns, nullptr, "target", 0);
    spawn(first_joiner, nullptr, "j1", 2);
    spawn(second_joiner, nullptr, "j2", 1);
    spawn_joinable(waits_on_itself, nullptr, "self", 3);
    ASSERT_EQ(chm_kernel_run(), 0);
}

// ---- end hooks and task-local values
chm_task_key_t g_key;
void note_hook(void* what) { g_log.push_back(static_cast<const char*>(what)); }
void note_value(void* v) { g_log.push_back(std::string("value ") + static_cast<const char*>(v)); }

void with_hooks(void* how) {
    ASSERT_EQ(chm_task_on_end(note_hook, (void*)"first"), 0);
    ASSERT_EQ(chm_task_on_end(note_hook, (void*)"second"), 0);
    ASSERT_EQ(chm_task_set_local(g_key, (void*)"mine"), 0);
    EXPECT_STREQ(static_cast<const char*>(chm_task_get_local(g_key)), "mine");
    const std::string h = static_cast<const char*>(how);
    if (h == "exit") chm_task_exit();
    if (h == "abort") chm_err_invoke(CHM_ERR_KERNEL, CHM_EK_CANARY);
    if (h == "destroy" || h == "teardown")
        for (;;) chm_task_pause_until(chm_time_now() + 1000 * kMs);  // until someone ends it
}

struct HookCase {
    const char* how;
    bool destroy;
};
void destroyer(void* p) {
    const auto* c = static_cast<const HookCase*>(p);
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.priority = 2;  // runs at once, then waits for us
    chm_tid_t id;
    ASSERT_EQ(chm_task_spawn(&id, with_hooks, (void*)c->how, &a), 0);
    if (c->destroy) {
        ASSERT_EQ(chm_task_destroy(id), 0);
        g_log.push_back("destroyed");
    }
}

TEST_F(Lifecycle, EndHooksAndLocalValuesRunWhicheverWayATaskEnds) {
    ASSERT_EQ(chm_task_key_create(&g_key, note_value), 0);
    const std::vector<std::string> hooks{"second", "first", "value mine"};
    for (const HookCase c : {HookCase{"return", false}, HookCase{"exit", false}, HookCase{"abort", false},
                             HookCase{"destroy", true}, HookCase{"teardown", false}}) {
        start(CHM_SCHED_FIXED);
        g_log.clear();
        spawn(destroyer, (void*)&c, "destroyer", 1);
        if (std::string(c.how) == "teardown") {
            // The task spins for ever: stop the kernel with it still there.
            chm_task_attr_t a;
            chm_task_attr_init(&a);
            a.priority = 3;
            a.period_ns = 10 * kMs;
            a.start_ns = 5 * kMs;
            ASSERT_EQ(chm_task_spawn(nullptr, [](void*) { chm_kernel_stop(0); }, nullptr, &a), 0);
        }
        ASSERT_EQ(chm_kernel_run(), 0);
        chm_kernel_fini();
        started_ = false;
        std::vector<std::string> want = hooks;
        if (c.destroy) want.push_back("destroyed");
        EXPECT_EQ(g_log, want) << c.how;
    }
    chm_task_key_t k2;
    EXPECT_EQ(chm_task_key_create(&k2, nullptr), 0);
    EXPECT_NE(k2, g_key);
    EXPECT_EQ(chm_task_key_create(nullptr, nullptr), -EINVAL);
}

void values_are_per_task(void* v) {
    EXPECT_EQ(chm_task_get_local(g_key), nullptr) << "a new task's value starts NULL";
    ASSERT_EQ(chm_task_set_local(g_key, v), 0);
    chm_time_consume(kMs);  // the other task runs and sets its own
    EXPECT_EQ(chm_task_get_local(g_key), v);
    ASSERT_EQ(chm_task_set_local(g_key, nullptr), 0);  // no destructor for NULL
}

TEST_F(Lifecycle, LocalValuesArePerTask) {
    start(CHM_SCHED_FIXED, true, kMs / 2);
    g_log.clear();
    spawn(values_are_per_task, (void*)"a", "a", 1);
    spawn(values_are_per_task, (void*)"b", "b", 1);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_TRUE(g_log.empty());
    EXPECT_EQ(chm_task_set_local(9999, nullptr), -EINVAL);
    EXPECT_EQ(chm_task_on_end(nullptr, nullptr), -EINVAL);
}

// ---- timing changes at the next release
std::vector<std::uint64_t> g_releases, g_deadlines;
chm_tid_t g_self;
chm_deadline_action note_deadline(const chm_deadline_info_t* info, void*) {
    g_deadlines.push_back(info->deadline_ns);
    return CHM_DL_CONTINUE;
}
void retimed(void*) {
    for (int c = 0; c < 6; ++c) {
        g_releases.push_back(chm_task_cycle_release());
        chm_task_status_t st;
        if (c == 2) {
            const chm_task_timing_t t{5 * kMs, 4 * kMs, 4 * kMs, 0};
            ASSERT_EQ(chm_task_set_timing(chm_task_self(), &t), 0);
            ASSERT_EQ(chm_task_status(chm_task_self(), &st), 0);
            EXPECT_EQ(st.period_ns, 10 * kMs) << "not before the next release";
        }
        if (c == 4) chm_time_consume(4 * kMs + 1);  // past the new deadline (4 ms)
        ASSERT_EQ(chm_task_wait_period(), 0);
    }
}
void hog(void*) { chm_time_consume(100 * kMs); }

TEST_F(Lifecycle, ATimingChangeTakesEffectAtTheNextReleaseOnTheGrid) {
    start(CHM_SCHED_MUF);
    g_releases.clear();
    g_deadlines.clear();
    // A busy aperiodic task beside it takes whatever CPU it leaves.
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = "retimed";
    a.period_ns = 10 * kMs;
    a.wcet_ns = 1 * kMs;
    a.on_deadline = note_deadline;
    ASSERT_EQ(chm_task_spawn(&g_self, retimed, nullptr, &a), 0);
    spawn(hog, nullptr, "hog");
    ASSERT_EQ(chm_kernel_run(), 0);
    // Releases 0, 10, 20; the change made in cycle 2 applies at 30 (where
    // the old period put it), then every 5 ms.
    EXPECT_EQ(g_releases, (std::vector<std::uint64_t>{0, 10 * kMs, 20 * kMs, 30 * kMs, 35 * kMs, 40 * kMs}));
    EXPECT_EQ(g_deadlines, (std::vector<std::uint64_t>{35 * kMs + 4 * kMs}))
        << "cycle 4 (released at 35 ms) misses its new 4 ms deadline";
    chm_task_status_t st;
    ASSERT_EQ(chm_task_status(g_self, &st), 0);
    EXPECT_EQ(st.period_ns, 5 * kMs);
    EXPECT_EQ(st.deadline_ns, 4 * kMs);
    EXPECT_EQ(st.wcet_ns, 4 * kMs);
}

// MUF's critical set follows a change: B leaves it when its estimate grows.
std::vector<int> g_b_critical;
void b_body(void*) {
    for (int c = 0; c < 3; ++c) {
        chm_task_status_t st;
        ASSERT_EQ(chm_task_status(chm_task_self(), &st), 0);
        g_b_critical.push_back(st.critical);
        if (c == 0) {
            const chm_task_timing_t t{20 * kMs, 20 * kMs, 10 * kMs, 0};  // U 0.6 + 0.5 > 1
            ASSERT_EQ(chm_task_set_timing(chm_task_self(), &t), 0);
        }
        ASSERT_EQ(chm_task_wait_period(), 0);
    }
}
void a_body(void*) {
    for (int c = 0; c < 6; ++c) ASSERT_EQ(chm_task_wait_period(), 0);
}

TEST_F(Lifecycle, MufsCriticalSetFollowsATimingChangeAtTheRelease) {
    start(CHM_SCHED_MUF);
    g_b_critical.clear();
    spawn(a_body, nullptr, "a", 0, 10 * kMs, 6 * kMs);
    spawn(b_body, nullptr, "b", 0, 20 * kMs, 6 * kMs);  // U 0.6 + 0.3: both critical
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_b_critical, (std::vector<int>{1, 0, 0}));
}

void refusals(void*) {
    chm_task_timing_t t{10 * kMs, 0, kMs, 0};
    EXPECT_EQ(chm_task_set_timing(chm_task_self(), &t), -EINVAL) << "an aperiodic task";
    EXPECT_EQ(chm_task_set_timing(chm_task_self(), nullptr), -EINVAL);
    EXPECT_EQ(chm_task_set_timing(0x7fff0000, &t), -ESRCH);
    const chm_task_timing_t bad[] = {{0, 0, 0, 0}, {10 * kMs, 11 * kMs, 0, 0}, {10 * kMs, 5 * kMs, 6 * kMs, 0}};
    for (const auto& b : bad) EXPECT_EQ(chm_task_set_timing(g_self, &b), -EINVAL);
    EXPECT_EQ(chm_task_set_timing(g_self, &t), 0);
    (void)chm_task_destroy(g_self);
}
void periodic_idle(void*) {
    for (;;) chm_task_wait_period();
}

TEST_F(Lifecycle, ATimingChangeThatCannotHoldIsRefused) {
    start(CHM_SCHED_MUF);
    g_self = spawn(periodic_idle, nullptr, "p", 0, 10 * kMs, kMs);
    spawn(refusals, nullptr, "r", 1);
    ASSERT_EQ(chm_kernel_run(), 0);
}

}  // namespace
}  // namespace chm::test
