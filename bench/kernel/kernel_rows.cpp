// Kernel rows of the report: task management and local semaphores, measured
// inside real kernel tasks on the real clock. Each measurement runs a small
// kernel (FIXED priorities, no quantum) on the bench's pinned CPU, times
// `runs` runs of n operations with the monotonic clock inside the tasks, and
// emits the median ns per operation with min and max.
#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include "../harness.hpp"
#include "chimera/chimera.h"
#include "port.hpp"

namespace chm::bench {
namespace {

struct Series {
    std::vector<double> ns_per_op;
    void add(std::uint64_t t0, std::uint64_t t1, double ops) { ns_per_op.push_back(double(t1 - t0) / ops); }
    Stats stats() const {
        std::vector<double> v = ns_per_op;
        std::sort(v.begin(), v.end());
        Stats s;
        if (v.empty()) return s;
        s.median = v[v.size() / 2];
        s.min = v.front();
        s.max = v.back();
        s.runs = int(v.size());
        return s;
    }
};

int runs_for(const Session& s) { return s.options().quick ? 11 : 101; }

struct Kernel {
    explicit Kernel(int accounting = 1) {
        chm_kernel_config_t cfg;
        chm_kernel_config_init(&cfg);
        cfg.cpu_accounting = accounting;
        cfg.policy = CHM_SCHED_FIXED;
        cfg.quantum_ns = 0;
        cfg.default_stack = 256 * 1024;
        ok = chm_kernel_init(&cfg) == 0;
    }
    ~Kernel() { chm_kernel_fini(); }
    bool ok;
};

chm_tid_t spawn(void (*fn)(void*), void* arg, int prio) {
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.priority = prio;
    chm_tid_t id = CHM_TID_NONE;
    chm_task_spawn(&id, fn, arg, &a);
    return id;
}

std::string cfg_text(Session& s, const char* what) {
    return "pinned " + s.cpu_name(0) + ", one RTPU, FIXED policy, " + what;
}

// ---- yield to an equal task: two tasks ping-pong through chm_task_yield
struct YieldArgs {
    int runs, n;
    Series series;
    volatile bool done = false;
};
void yielder_a(void* p) {
    auto* a = static_cast<YieldArgs*>(p);
    for (int r = 0; r < a->runs; ++r) {
        const std::uint64_t t0 = port::now_ns();
        for (int i = 0; i < a->n; ++i) chm_task_yield();
        a->series.add(t0, port::now_ns(), 2.0 * a->n);  // each yield: 2 switches per round
    }
    a->done = true;
}
void yielder_b(void* p) {
    auto* a = static_cast<YieldArgs*>(p);
    while (!a->done) chm_task_yield();
}

void yield_rows(Session& s) {
    Session::pin(s.cpu(0));
    Kernel k(0);
    if (!k.ok) throw std::runtime_error("kernel init failed");
    YieldArgs a{runs_for(s), 20000, {}};
    spawn(yielder_a, &a, 1);
    spawn(yielder_b, &a, 1);
    chm_kernel_run();
    const Stats st = a.series.stats();
    s.emit("yield_switch", cfg_text(s, "two equal tasks, chm_task_yield; one switch; cpu_accounting 0 (CPU time charged at ticks)"), st.median, st.min, st.max);
    s.emit("context_switch_fpu",
           cfg_text(s, "task-to-task switch saving callee-saved registers and the FP control state "
                       "(FP data registers are caller-saved in the ABI, so a voluntary switch never holds any)"),
           st.median, st.min, st.max);
}
CHM_BENCH_MEASUREMENT(yield_rows, "yield_switch", "context_switch_fpu");

// ---- uncontended P and V
struct PvArgs {
    Session* s;
    int runs, n;
    Series pv, p, v;
};
void pv_task(void* arg) {
    auto* a = static_cast<PvArgs*>(arg);
    chm_sem_t sem;
    chm_sem_init(&sem, CHM_SEM_COUNTING, 1, 0);
    for (int r = 0; r < a->runs; ++r) {
        std::uint64_t t0 = port::now_ns();
        for (int i = 0; i < a->n; ++i) {
            chm_sem_p(&sem);
            chm_sem_v(&sem);
        }
        a->pv.add(t0, port::now_ns(), a->n);
        t0 = port::now_ns();
        for (int i = 0; i < a->n; ++i) chm_sem_v(&sem);
        a->v.add(t0, port::now_ns(), a->n);
        t0 = port::now_ns();
        for (int i = 0; i < a->n; ++i) chm_sem_p(&sem);
        a->p.add(t0, port::now_ns(), a->n);
    }
    chm_sem_destroy(&sem);
}

void pv_rows(Session& s) {
    Session::pin(s.cpu(0));
    Kernel k;
    PvArgs a{&s, runs_for(s), 100000, {}, {}, {}};
    spawn(pv_task, &a, 1);
    chm_kernel_run();
    Stats st = a.pv.stats();
    s.emit("local_pv_noblock", cfg_text(s, "chm_sem_p + chm_sem_v, counting, uncontended"), st.median, st.min, st.max);
    st = a.p.stats();
    s.emit("local_p_noblock", cfg_text(s, "chm_sem_p, unit available"), st.median, st.min, st.max);
    st = a.v.stats();
    s.emit("local_v_nowake", cfg_text(s, "chm_sem_v, nobody waiting"), st.median, st.min, st.max);
}
CHM_BENCH_MEASUREMENT(pv_rows, "local_pv_noblock", "local_p_noblock", "local_v_nowake");

// ---- V that wakes a more urgent task: low V()s, high wakes, P()s again
// and blocks, low resumes. One round = V-wake + switch + P-block + switch.
struct WakeArgs {
    int runs, n;
    chm_sem_t sem;
    Series rounds;
    volatile bool done = false;
};
void wake_high(void* p) {
    auto* a = static_cast<WakeArgs*>(p);
    while (!a->done) chm_sem_p(&a->sem);
}
void wake_low(void* p) {
    auto* a = static_cast<WakeArgs*>(p);
    for (int r = 0; r < a->runs; ++r) {
        const std::uint64_t t0 = port::now_ns();
        for (int i = 0; i < a->n; ++i) chm_sem_v(&a->sem);
        a->rounds.add(t0, port::now_ns(), a->n);
    }
    a->done = true;
    chm_sem_v(&a->sem);
}

void wake_rows(Session& s) {
    Session::pin(s.cpu(0));
    Kernel k(0);
    WakeArgs a{runs_for(s), 20000, {}, {}};
    chm_sem_init(&a.sem, CHM_SEM_BINARY, 0, 0);
    spawn(wake_high, &a, 9);
    spawn(wake_low, &a, 1);
    chm_kernel_run();
    const Stats r = a.rounds.stats();
    s.emit("sem_v_wake_switch", cfg_text(s, "V waking a higher-priority task incl. the switch to it (half a V-wake/P-block round); cpu_accounting 0"),
           r.median / 2, r.min / 2, r.max / 2);
    s.emit("local_v_wake", cfg_text(s, "half of a V-wake + P-block round between two tasks"), r.median / 2, r.min / 2, r.max / 2);
    s.emit("local_p_block", cfg_text(s, "half of a V-wake + P-block round between two tasks"), r.median / 2, r.min / 2, r.max / 2);
    s.emit("resource_contention_resched", cfg_text(s, "a task blocks on a semaphore and the next runs (half round)"),
           r.median / 2, r.min / 2, r.max / 2);
}
CHM_BENCH_MEASUREMENT(wake_rows, "sem_v_wake_switch", "local_v_wake", "local_p_block", "resource_contention_resched");

// ---- task spawn and destroy (stack pool warm)
void nop(void*) {}
struct SpawnArgs {
    int runs, n;
    Series both, create, destroy, prio;
    std::vector<chm_tid_t> ids;
};
void spawner(void* p) {
    auto* a = static_cast<SpawnArgs*>(p);
    a->ids.resize(std::size_t(a->n));
    for (int r = 0; r < a->runs; ++r) {
        std::uint64_t t0 = port::now_ns();
        for (int i = 0; i < a->n; ++i) chm_task_destroy(spawn(nop, nullptr, 1));
        a->both.add(t0, port::now_ns(), a->n);
        t0 = port::now_ns();
        for (int i = 0; i < a->n; ++i) a->ids[std::size_t(i)] = spawn(nop, nullptr, 1);
        a->create.add(t0, port::now_ns(), a->n);
        t0 = port::now_ns();
        for (int i = 0; i < a->n; ++i) chm_task_set_priority(a->ids[std::size_t(i)], 2 + (r & 1));
        a->prio.add(t0, port::now_ns(), a->n);
        t0 = port::now_ns();
        for (int i = 0; i < a->n; ++i) chm_task_destroy(a->ids[std::size_t(i)]);
        a->destroy.add(t0, port::now_ns(), a->n);
    }
}

void spawn_rows(Session& s) {
    Session::pin(s.cpu(0));
    Kernel k;
    SpawnArgs a{runs_for(s), 200, {}, {}, {}, {}, {}};
    spawn(spawner, &a, 9);
    chm_kernel_run();
    Stats st = a.both.stats();
    s.emit("task_spawn_destroy", cfg_text(s, "64 KiB stacks from the warm pool; spawn then destroy"), st.median, st.min, st.max);
    st = a.create.stats();
    s.emit("task_create", cfg_text(s, "default attributes, 64 KiB stack from the warm pool, 200 tasks ready"), st.median, st.min, st.max);
    st = a.destroy.stats();
    s.emit("task_destroy", cfg_text(s, "of a ready task"), st.median, st.min, st.max);
    st = a.prio.stats();
    s.emit("task_set_priority", cfg_text(s, "of a ready task (re-queued), 200 ready"), st.median, st.min, st.max);
}
CHM_BENCH_MEASUREMENT(spawn_rows, "task_spawn_destroy", "task_create", "task_destroy", "task_set_priority");

// ---- scheduler operations with 10 vs 10,000 ready tasks: re-prioritising
// a ready task (dequeue + enqueue + pick) under MUF with periodic keys.
struct SchedArgs {
    int runs, n, tasks;
    Series ops;
    std::vector<chm_tid_t> ids;
};
void sched_driver(void* p) {
    auto* a = static_cast<SchedArgs*>(p);
    for (int i = 0; i < a->tasks; ++i) a->ids.push_back(spawn(nop, nullptr, 1 + i % 7));
    for (int r = 0; r < a->runs; ++r) {
        const std::uint64_t t0 = port::now_ns();
        for (int i = 0; i < a->n; ++i)
            chm_task_set_priority(a->ids[std::size_t(i % a->tasks)], 1 + (i + r) % 7);
        a->ops.add(t0, port::now_ns(), a->n);
    }
    for (auto id : a->ids) chm_task_destroy(id);
}

double sched_cost(Session& s, int tasks) {
    Kernel k;
    SchedArgs a{runs_for(s), 20000, tasks, {}, {}};
    spawn(sched_driver, &a, 100);
    chm_kernel_run();
    return a.ops.stats().median;
}

void sched_scaling(Session& s) {
    Session::pin(s.cpu(0));
    const double c10 = sched_cost(s, 10);
    const double c10k = sched_cost(s, 10000);
    s.emit("sched_ops_10k_over_10",
           cfg_text(s, ("re-prioritise a ready task (dequeue+enqueue+pick): " + std::to_string(c10) +
                        " ns with 10 ready, " + std::to_string(c10k) + " ns with 10000")
                           .c_str()),
           c10k / c10, c10k / c10, c10k / c10);
}
CHM_BENCH_MEASUREMENT(sched_scaling, "sched_ops_10k_over_10");

}  // namespace
}  // namespace chm::bench
