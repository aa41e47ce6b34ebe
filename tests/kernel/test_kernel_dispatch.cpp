// The dispatcher's fast paths (built-in policies called directly, a yield
// or a preemption as one heap operation) against the behaviour they must
// keep: a user scheduler is still called through its operations table for
// every yield, round robin among equals with and without a quantum, and the
// ready heap orders many tasks exactly (priority, then arrival) through
// set_priority changes. Virtual clock: exact, no sleeping.
#include <algorithm>
#include <string>
#include <vector>

#include "kernel_fixture.hpp"

namespace chm::test {
namespace {

std::vector<Event> g_log;
void note(const std::string& who) { g_log.push_back({chm_time_now(), who}); }

// ---- a user FIFO scheduler that counts its calls
struct Fifo {
    std::vector<chm_sched_task_t*> q;
    int enqueues = 0, dequeues = 0, picks = 0, befores = 0;
};
Fifo g_fifo;
int f_admit(void*, chm_sched_task_t*) { return 0; }
void f_retire(void*, chm_sched_task_t*) {}
void f_enqueue(void* self, chm_sched_task_t* t, uint64_t) {
    auto* f = static_cast<Fifo*>(self);
    ++f->enqueues;
    f->q.push_back(t);
}
void f_dequeue(void* self, chm_sched_task_t* t) {
    auto* f = static_cast<Fifo*>(self);
    ++f->dequeues;
    f->q.erase(std::find(f->q.begin(), f->q.end(), t));
}
chm_sched_task_t* f_pick(void* self, uint64_t) {
    auto* f = static_cast<Fifo*>(self);
    ++f->picks;
    return f->q.empty() ? nullptr : f->q.front();
}
int f_before(void* self, const chm_sched_task_t*, const chm_sched_task_t*, uint64_t) {
    ++static_cast<Fifo*>(self)->befores;
    return 0;  // all equal: pure round robin
}
const chm_sched_ops_t kFifo = {"fifo", f_admit, f_retire, f_enqueue, f_dequeue,
                               f_pick, f_before, nullptr, nullptr};

struct Yielder {
    const char* name;
    int rounds;
};
void yielder(void* p) {
    auto* y = static_cast<Yielder*>(p);
    for (int i = 0; i < y->rounds; ++i) {
        note(y->name);
        chm_task_yield();
    }
}

class Dispatch : public KernelTest {
protected:
    void SetUp() override {
        g_log.clear();
        g_fifo = Fifo{};
    }
    std::string order() const {
        std::string s;
        for (const Event& e : g_log) s += e.who;
        return s;
    }
};

TEST_F(Dispatch, AUserSchedulerStillDecidesEveryYield) {
    start(CHM_SCHED_USER, true, 0, &kFifo, &g_fifo);
    static Yielder a{"a", 3}, b{"b", 3}, c{"c", 3};
    spawn(yielder, &a, "a", 1);
    spawn(yielder, &b, "b", 1);
    spawn(yielder, &c, "c", 1);
    const int enq0 = g_fifo.enqueues;
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(order(), "abcabcabc");
    // Every yield went through the table: re-enqueued, picked, dequeued.
    EXPECT_GE(g_fifo.enqueues - enq0, 9);
    EXPECT_GE(g_fifo.dequeues, 9);
    EXPECT_GE(g_fifo.picks, 9);
    EXPECT_EQ(chm_sched_fallbacks(), 0);
    EXPECT_EQ(chm_kernel_policy(), CHM_SCHED_USER);
}

TEST_F(Dispatch, ABuiltInTableInstalledAsUserSchedulerOrdersLikeTheBuiltIn) {
    start(CHM_SCHED_USER, true, 0, &chm_sched_fixed_ops, nullptr);
    static Yielder lo{"l", 2}, a{"a", 2}, b{"b", 2}, hi{"h", 1};
    spawn(yielder, &lo, "l", 1);
    spawn(yielder, &a, "a", 5);
    spawn(yielder, &b, "b", 5);
    spawn(yielder, &hi, "h", 9);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(order(), "hababll");
    EXPECT_EQ(chm_sched_fallbacks(), 0);
}

// Round robin among equals by yielding: the same with or without a quantum
// (the quantum only adds rotation of tasks that do not yield).
class YieldRoundRobin : public Dispatch, public ::testing::WithParamInterface<uint64_t> {};

TEST_P(YieldRoundRobin, EqualsTakeTurnsAndALowerTaskWaits) {
    start(CHM_SCHED_FIXED, true, GetParam());
    static Yielder a{"a", 3}, b{"b", 3}, c{"c", 3}, lo{"l", 1};
    spawn(yielder, &lo, "l", 1);
    spawn(yielder, &a, "a", 4);
    spawn(yielder, &b, "b", 4);
    spawn(yielder, &c, "c", 4);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(order(), "abcabcabcl");
}
INSTANTIATE_TEST_SUITE_P(Quantum, YieldRoundRobin, ::testing::Values(0, 2 * kMs));

// Tasks that never yield: a quantum rotates equals at its exact expiry;
// without one, each runs to its end.
struct Burner {
    const char* name;
};
void burner(void* p) {
    for (int i = 0; i < 5; ++i) {
        note(static_cast<Burner*>(p)->name);
        chm_time_consume(kMs);
    }
}

TEST_F(Dispatch, WithoutAQuantumEqualsRunToTheirEnd) {
    start(CHM_SCHED_FIXED, true, 0);
    static Burner a{"a"}, b{"b"};
    spawn(burner, &a, "a", 3);
    spawn(burner, &b, "b", 3);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(order(), "aaaaabbbbb");
    EXPECT_EQ(g_log[5].t, 5 * kMs);
}

TEST_F(Dispatch, AQuantumRotatesEqualsAtItsExpiry) {
    start(CHM_SCHED_FIXED, true, 2 * kMs);
    static Burner a{"a"}, b{"b"};
    spawn(burner, &a, "a", 3);
    spawn(burner, &b, "b", 3);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(order(), "aabbaabbab");
    std::vector<uint64_t> at;
    for (const Event& e : g_log) at.push_back(e.t / kMs);
    EXPECT_EQ(at, (std::vector<uint64_t>{0, 1, 2, 3, 4, 5, 6, 7, 8, 9}));
}

// ---- many tasks through the ready heap: run order is priority, then the
// order in which they became ready; set_priority on a waiting task keeps
// its arrival.
constexpr int kMany = 300;
std::vector<int> g_ran;
struct Many {
    int index;
    int prio;
};
Many g_many[kMany];
void many_body(void* p) { g_ran.push_back(static_cast<Many*>(p)->index); }
void many_driver(void*) {
    unsigned x = 12345;
    std::vector<chm_tid_t> ids;
    for (int i = 0; i < kMany; ++i) {
        x = x * 1103515245u + 12345u;
        g_many[i] = {i, 1 + int((x >> 16) % 20)};
        chm_task_attr_t a;
        chm_task_attr_init(&a);
        a.priority = g_many[i].prio;
        a.stack_size = 16 * 1024;
        chm_tid_t id = CHM_TID_NONE;
        ASSERT_EQ(chm_task_spawn(&id, many_body, &g_many[i], &a), 0);
        ids.push_back(id);
    }
    for (int i = 0; i < kMany; i += 7) {  // re-prioritise some while they wait
        g_many[i].prio = 1 + (g_many[i].prio * 7) % 20;
        ASSERT_EQ(chm_task_set_priority(ids[std::size_t(i)], g_many[i].prio), 0);
    }
}

TEST_F(Dispatch, TheReadyHeapOrdersManyTasksByPriorityThenArrival) {
    for (chm_sched_policy p : {CHM_SCHED_FIXED, CHM_SCHED_MUF}) {
        g_ran.clear();
        start(p, true, 0);
        spawn(many_driver, nullptr, "driver", 100, 0, 0, /*critical=*/1);
        ASSERT_EQ(chm_kernel_run(), 0);
        chm_kernel_fini();
        started_ = false;
        std::vector<int> want(kMany);
        for (int i = 0; i < kMany; ++i) want[std::size_t(i)] = i;
        std::stable_sort(want.begin(), want.end(),
                         [](int a, int b) { return g_many[a].prio > g_many[b].prio; });
        EXPECT_EQ(g_ran, want) << "policy " << int(p);
    }
}

}  // namespace
}  // namespace chm::test
