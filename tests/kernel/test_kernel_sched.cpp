// The scheduler behaviour suite, on the virtual clock with hand-computed
// schedules: one suite instantiated for RM, EDF, MLF, MUF and a user
// scheduler, then the cases where the policies must differ.
#include <cerrno>
#include <map>

#include "kernel_fixture.hpp"

namespace chm::test {
namespace {

std::string g_trace;  // one letter per 0.5 ms slot of CPU

struct Job {
    const char* name;
    uint64_t wcet;
    int cycles;
    uint64_t period;  // released at 0, k*period
};

// A periodic task: each cycle consumes its wcet in 0.5 ms slots.
void periodic_body(void* p) {
    const Job* j = static_cast<const Job*>(p);
    for (int c = 0; c < j->cycles; ++c) {
        for (uint64_t used = 0; used < j->wcet; used += kMs / 2) {
            chm_time_consume(kMs / 2);
            g_trace += j->name[0];  // once the slot ran (see long_runner)
        }
        if (c + 1 < j->cycles) {
            ASSERT_EQ(chm_task_wait_period(), 0);
        } else {
            // Stay in the set until the last period ends (MUF's critical
            // set changes when a task leaves), without a new release.
            ASSERT_EQ(chm_task_pause_until(uint64_t(j->cycles) * j->period), 0);
        }
    }
}

uint64_t misses_of(chm_tid_t id) {
    chm_task_status_t st;
    // Ended tasks are gone; the tests read statistics before they end.
    return chm_task_status(id, &st) == 0 ? st.misses : UINT64_MAX;
}

// Record per-task misses when each task ends (its status disappears then).
std::map<std::string, uint64_t> g_misses;
void periodic_then_report(void* p) {
    periodic_body(p);
    const Job* j = static_cast<const Job*>(p);
    g_misses[j->name] = misses_of(chm_task_self());
}

// ---- a user scheduler: EDF kept in a sorted singly linked list (O(n)
// insertion is fine for a test; the kernel only sees the ops table).
struct UserEdf {
    chm_sched_task_t* head = nullptr;
    int admitted = 0;
};
chm_sched_task_t*& next_of(chm_sched_task_t* t) { return *reinterpret_cast<chm_sched_task_t**>(&t->data); }
int u_admit(void* self, chm_sched_task_t* t) {
    ++static_cast<UserEdf*>(self)->admitted;
    next_of(t) = nullptr;
    return 0;
}
void u_retire(void*, chm_sched_task_t*) {}
int u_before(void*, const chm_sched_task_t* a, const chm_sched_task_t* b, uint64_t) {
    if (a->abs_deadline_ns != b->abs_deadline_ns) return a->abs_deadline_ns < b->abs_deadline_ns;
    return a->priority > b->priority;
}
void u_enqueue(void* self, chm_sched_task_t* t, uint64_t now) {
    auto* s = static_cast<UserEdf*>(self);
    chm_sched_task_t** link = &s->head;
    while (*link && !u_before(self, t, *link, now) &&
           (u_before(self, *link, t, now) || (*link)->seq < t->seq))
        link = &next_of(*link);
    next_of(t) = *link;
    *link = t;
}
void u_dequeue(void* self, chm_sched_task_t* t) {
    auto* s = static_cast<UserEdf*>(self);
    for (chm_sched_task_t** link = &s->head; *link; link = &next_of(*link))
        if (*link == t) {
            *link = next_of(t);
            return;
        }
}
chm_sched_task_t* u_pick(void* self, uint64_t) { return static_cast<UserEdf*>(self)->head; }
const chm_sched_ops_t kUserEdf = {"user-edf", u_admit, u_retire, u_enqueue, u_dequeue,
                                  u_pick, u_before, nullptr, nullptr};
UserEdf g_user;

// ---- the common suite
class EverySched : public KernelTest, public ::testing::WithParamInterface<chm_sched_policy> {
protected:
    void SetUp() override {
        g_trace.clear();
        g_misses.clear();
        g_user = UserEdf{};
        const auto p = GetParam();
        start(p, true, 0, p == CHM_SCHED_USER ? &kUserEdf : nullptr, &g_user);
    }
};

std::vector<uint64_t> g_releases;
void grid_body(void*) {
    for (int c = 0; c < 10; ++c) {
        g_releases.push_back(chm_time_now());
        chm_time_consume(3 * kMs + 333);  // odd amounts must not shift the grid
        ASSERT_EQ(chm_task_wait_period(), 0);
    }
}

TEST_P(EverySched, PeriodicReleasesStayOnTheAbsoluteGrid) {
    g_releases.clear();
    spawn(grid_body, nullptr, "grid", 1, 10 * kMs, 4 * kMs);
    ASSERT_EQ(chm_kernel_run(), 0);
    ASSERT_EQ(g_releases.size(), 10u);
    for (size_t k = 0; k < g_releases.size(); ++k) EXPECT_EQ(g_releases[k], k * 10 * kMs);
}

TEST_P(EverySched, UnderloadedHarmonicSetMeetsEveryDeadline) {
    // U = 0.25 + 0.2 + 0.15 = 0.6
    static Job a{"a", 1 * kMs, 20, 4 * kMs}, b{"b", 2 * kMs, 10, 10 * kMs}, c{"c", 3 * kMs, 5, 20 * kMs};
    spawn(periodic_then_report, &a, "a", 1, 4 * kMs, a.wcet);
    spawn(periodic_then_report, &b, "b", 2, 10 * kMs, b.wcet);
    spawn(periodic_then_report, &c, "c", 3, 20 * kMs, c.wcet);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_misses["a"], 0u);
    EXPECT_EQ(g_misses["b"], 0u);
    EXPECT_EQ(g_misses["c"], 0u);
    if (GetParam() == CHM_SCHED_USER) {
        EXPECT_EQ(g_user.admitted, 3);
    }
    EXPECT_EQ(chm_sched_fallbacks(), 0);
}

void urgent_once(void*) {
    chm_time_consume(kMs / 2);
    g_trace += 'U';
}
// A slot is noted once it ran: at the instant a task's work ends it runs on
// to its next kernel call before what else happens then is acted on
// (sched.h), so a note taken before the next slot would come before a
// preemption at that instant.
void long_runner(void*) {
    for (int i = 0; i < 6; ++i) {
        chm_time_consume(kMs / 2);
        g_trace += 'L';
    }
}

TEST_P(EverySched, AnUrgentReleasePreemptsAtItsExactTime) {
    // L is aperiodic (least urgent under every policy); U is released at
    // 1 ms with a 2 ms period and deadline.
    spawn(long_runner, nullptr, "L", 0);
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = "U";
    a.priority = 5;
    a.period_ns = 2 * kMs;
    a.wcet_ns = kMs / 2;
    a.start_ns = 1 * kMs;
    chm_tid_t id;
    ASSERT_EQ(chm_task_spawn(&id, urgent_once, nullptr, &a), 0);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_trace, "LLULLLL");
}

INSTANTIATE_TEST_SUITE_P(Policies, EverySched,
                         ::testing::Values(CHM_SCHED_RM, CHM_SCHED_EDF, CHM_SCHED_MLF,
                                           CHM_SCHED_MUF, CHM_SCHED_USER),
                         [](const auto& info) {
                             switch (info.param) {
                             case CHM_SCHED_RM: return std::string("RM");
                             case CHM_SCHED_EDF: return std::string("EDF");
                             case CHM_SCHED_MLF: return std::string("MLF");
                             case CHM_SCHED_MUF: return std::string("MUF");
                             default: return std::string("User");
                             }
                         });

// ---- where the policies differ
class Differ : public KernelTest {
protected:
    void SetUp() override {
        g_trace.clear();
        g_misses.clear();
    }
    void full_utilisation_set() {
        // T1 (P 2, C 1) + T2 (P 5, C 2.5): U = 1.0; 20 ms of it.
        static Job t1{"1", 1 * kMs, 10, 2 * kMs}, t2{"2", 5 * kMs / 2, 4, 5 * kMs};
        spawn(periodic_then_report, &t1, "1", 0, 2 * kMs, t1.wcet);
        spawn(periodic_then_report, &t2, "2", 0, 5 * kMs, t2.wcet);
    }
    // Misses whose deadline falls in the first 160 ms (four hyperperiods of
    // the critical tasks), counted by a deadline-failure handler; the tasks
    // run on to 240 ms so that none leaves the set inside the window.
    static chm_deadline_action count_miss(const chm_deadline_info_t* info, void* arg) {
        if (info->deadline_ns <= 160 * kMs) ++g_misses[static_cast<const Job*>(arg)->name];
        return CHM_DL_CONTINUE;
    }
    void spawn_counted(Job* j, int critical) {
        chm_task_attr_t a;
        chm_task_attr_init(&a);
        a.name = j->name;
        a.period_ns = j->period;
        a.wcet_ns = j->wcet;
        a.critical = critical;
        a.on_deadline = count_miss;
        a.on_deadline_arg = j;
        chm_tid_t id;
        ASSERT_EQ(chm_task_spawn(&id, periodic_body, j, &a), 0);
    }
    void overload_set() {
        // U = 0.5 + 0.5 + 0.3 = 1.3; C is marked critical by the user.
        static Job a{"A", 5 * kMs, 24, 10 * kMs}, b{"B", 10 * kMs, 12, 20 * kMs},
            c{"C", 12 * kMs, 6, 40 * kMs};
        spawn_counted(&a, 0);
        spawn_counted(&b, 0);
        spawn_counted(&c, 1);
    }
};

TEST_F(Differ, EdfSchedulesFullUtilisationExactly) {
    start(CHM_SCHED_EDF);
    full_utilisation_set();
    ASSERT_EQ(chm_kernel_run(), 0);
    // Hand-computed: slots of 0.5 ms over the first 10 ms.
    EXPECT_EQ(g_trace.substr(0, 20), "11221122211211222211");
    EXPECT_EQ(g_misses["1"], 0u);
    EXPECT_EQ(g_misses["2"], 0u);
}

TEST_F(Differ, RateMonotonicMissesTheSameSet) {
    start(CHM_SCHED_RM);
    full_utilisation_set();
    ASSERT_EQ(chm_kernel_run(), 0);
    // T1 always first: T2 has 2 of its 2.5 ms at its deadline (5 ms).
    EXPECT_EQ(g_trace.substr(0, 10), "1122112211");
    EXPECT_EQ(g_misses["1"], 0u);
    EXPECT_GE(g_misses["2"], 1u);
}

TEST_F(Differ, MlfAndEdfOrderTheSameJobsDifferently) {
    static Job j1{"x", 2 * kMs, 1, 10 * kMs}, j2{"y", 8 * kMs, 1, 12 * kMs};
    for (auto policy : {CHM_SCHED_EDF, CHM_SCHED_MLF}) {
        g_trace.clear();
        g_misses.clear();
        start(policy);
        // x: deadline 10, needs 2 (laxity 8); y: deadline 12, needs 8 (laxity 4).
        spawn(periodic_then_report, &j1, "x", 0, 10 * kMs, j1.wcet);
        spawn(periodic_then_report, &j2, "y", 0, 12 * kMs, j2.wcet);
        ASSERT_EQ(chm_kernel_run(), 0);
        if (policy == CHM_SCHED_EDF)
            EXPECT_EQ(g_trace, "xxxxyyyyyyyyyyyyyyyy") << "EDF: earliest deadline first";
        else
            EXPECT_EQ(g_trace, "yyyyyyyyyyyyyyyyxxxx") << "MLF: least laxity first";
        EXPECT_EQ(g_misses["x"], 0u);
        EXPECT_EQ(g_misses["y"], 0u);
        chm_kernel_fini();
    }
    started_ = false;
}

TEST_F(Differ, MufKeepsCriticalTasksOnTimeInTransientOverload) {
    start(CHM_SCHED_MUF);
    overload_set();
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_misses["A"], 0u) << g_trace;
    EXPECT_EQ(g_misses["C"], 0u) << g_trace;
    EXPECT_GT(g_misses["B"], 0u) << "only the non-critical task absorbs the overload";
}

TEST_F(Differ, RmMissesTheCriticalTaskInTheSameOverload) {
    start(CHM_SCHED_RM);
    overload_set();
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_GT(g_misses["C"], 0u) << "RM starves the long-period task, critical or not";
}

TEST_F(Differ, EdfMissesCriticalTasksInTheSameOverload) {
    start(CHM_SCHED_EDF);
    overload_set();
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_GT(g_misses["A"] + g_misses["C"], 0u) << "EDF has no notion of criticality";
}

// ---- a user scheduler that fails
chm_sched_task_t g_bogus{};
chm_sched_task_t* bad_pick(void* self, uint64_t now) {
    static int calls = 0;
    return ++calls > 3 ? &g_bogus : u_pick(self, now);
}
const chm_sched_ops_t kBroken = {"broken", u_admit, u_retire, u_enqueue, u_dequeue,
                                 bad_pick, u_before, nullptr, nullptr};

TEST_F(Differ, AFailingUserSchedulerFallsBackToMuf) {
    g_user = UserEdf{};
    start(CHM_SCHED_USER, true, 0, &kBroken, &g_user);
    static Job a{"a", 1 * kMs, 5, 5 * kMs}, b{"b", 2 * kMs, 5, 10 * kMs};
    spawn(periodic_then_report, &a, "a", 1, 5 * kMs, a.wcet);
    spawn(periodic_then_report, &b, "b", 2, 10 * kMs, b.wcet);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(chm_sched_fallbacks(), 1);
    EXPECT_EQ(chm_kernel_policy(), CHM_SCHED_MUF);
    EXPECT_NE(std::string(chm_sched_fallback_reason()).find("broken"), std::string::npos);
    EXPECT_EQ(g_trace.size(), 5u * 2 + 5u * 4) << "every cycle of both tasks still ran";
}

}  // namespace
}  // namespace chm::test
