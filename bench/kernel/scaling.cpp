// Scheduler cost against the number of tasks (10 to 10,000): the PERF.md
// row sched_ops_10k_over_10 and the data of docs/bench/scaling_tasks.png.
// For each N, a kernel holds N ready tasks that never run (priorities 1-7,
// 16 KiB stacks) under the operations timed by a priority-50 driver:
//   set_priority    re-prioritise one of the N ready tasks (dequeue, enqueue)
//   yield           the driver and an equal partner yield to each other (/2)
//   v_wake_round    V waking a priority-60 task blocked in P, which P's again
//                   and blocks: a V-wake-switch + P-block-switch round
//   spawn_destroy   spawn and destroy an aperiodic task (FIXED policy)
//   muf_periodic_spawn_destroy  the same for a periodic task under MUF with
//                   N periodic tasks alive (admission updates the critical
//                   set incrementally: O(log N); shown, not in the value)
#include <cstdio>
#include <map>

#include "kbench.hpp"

namespace chm::bench {
namespace {

constexpr std::uint64_t kHour = 3600ull * 1000000000ull;

void nop(void*) {}

struct Partner {
    volatile bool stop = false;
    chm_sem_t sem;
};
void yield_partner(void* p) {
    auto* a = static_cast<Partner*>(p);
    while (!a->stop) chm_task_yield();
}
void sem_partner(void* p) {
    auto* a = static_cast<Partner*>(p);
    while (!a->stop) chm_sem_p(&a->sem);
}

using Costs = std::map<std::string, Stats>;

void fixed_ops(Session& s, int tasks, Costs& out) {
    kb::Kernel k;
    Partner a;
    chm_sem_init(&a.sem, CHM_SEM_BINARY, 0, 0);
    std::vector<chm_tid_t> ids;
    std::function<void()> driver = [&] {
        kb::TaskSpec bg;
        bg.stack = 16 * 1024;
        for (int i = 0; i < tasks; ++i) {
            bg.priority = 1 + i % 7;
            ids.push_back(kb::spawn(nop, nullptr, bg));
        }
        std::uint64_t r = 0;
        out["set_priority"] = s.measure([&](std::uint64_t n) {
            const std::uint64_t t0 = mono_ns();
            for (std::uint64_t i = 0; i < n; ++i, ++r)
                chm_task_set_priority(ids[std::size_t(r % std::uint64_t(tasks))], 1 + int((r / 3) % 7));
            return double(mono_ns() - t0);
        });
        out["spawn_destroy"] = s.measure([&](std::uint64_t n) {
            kb::TaskSpec t;
            t.priority = 1;
            t.stack = 16 * 1024;
            const std::uint64_t t0 = mono_ns();
            for (std::uint64_t i = 0; i < n; ++i) chm_task_destroy(kb::spawn(nop, nullptr, t));
            return double(mono_ns() - t0);
        });
        kb::TaskSpec hi;
        hi.priority = 60;
        hi.stack = 16 * 1024;
        const chm_tid_t waker = kb::spawn(sem_partner, &a, hi);  // runs, blocks in P
        out["v_wake_round"] = s.measure([&](std::uint64_t n) {
            const std::uint64_t t0 = mono_ns();
            for (std::uint64_t i = 0; i < n; ++i) chm_sem_v(&a.sem);
            return double(mono_ns() - t0);
        });
        chm_task_destroy(waker);
        kb::TaskSpec eq;
        eq.priority = 50;
        eq.stack = 16 * 1024;
        kb::spawn(yield_partner, &a, eq);
        out["yield"] = s.measure([&](std::uint64_t n) {
            const std::uint64_t t0 = mono_ns();
            for (std::uint64_t i = 0; i < n; ++i) chm_task_yield();
            return double(mono_ns() - t0);
        }, 2);
        a.stop = true;
        for (auto id : ids) chm_task_destroy(id);
    };
    kb::TaskSpec d;
    d.priority = 50;
    kb::spawn_fn(&driver, d);
    k.run();
    chm_sem_destroy(&a.sem);
}

void muf_spawn(Session& s, int tasks, Costs& out) {
    kb::Kernel k({CHM_SCHED_MUF, 1});
    std::function<void()> driver = [&] {
        const std::uint64_t far = chm_time_now() + kHour;  // never released during the run
        kb::TaskSpec bg;
        bg.stack = 16 * 1024;
        bg.period_ns = 1000000000;
        bg.wcet_ns = 1000;
        bg.start_ns = far;
        std::vector<chm_tid_t> ids;
        for (int i = 0; i < tasks; ++i) ids.push_back(kb::spawn(nop, nullptr, bg));
        out["muf_periodic_spawn_destroy"] = s.measure([&](std::uint64_t n) {
            const std::uint64_t t0 = mono_ns();
            for (std::uint64_t i = 0; i < n; ++i) chm_task_destroy(kb::spawn(nop, nullptr, bg));
            return double(mono_ns() - t0);
        });
        for (auto id : ids) chm_task_destroy(id);
    };
    kb::TaskSpec d;
    d.critical = 1;  // aperiodic driver: critical, so it outranks the periodic set
    kb::spawn_fn(&driver, d);
    k.run();
}

void sched_scaling(Session& s) {
    Session::pin(s.cpu(0));
    const std::vector<int> counts = {10, 100, 1000, 10000};
    std::vector<Costs> costs;
    for (int n : counts) {
        Costs c;
        fixed_ops(s, n, c);
        muf_spawn(s, n, c);
        costs.push_back(c);
    }
    // The JSON for run.py: medians and min–max per operation and N.
    std::string js = "{\"tasks\": [";
    for (std::size_t i = 0; i < counts.size(); ++i) js += (i ? ", " : "") + std::to_string(counts[i]);
    js += "], \"unit\": \"ns\", \"ops\": {";
    bool first = true;
    for (const auto& [op, st0] : costs[0]) {
        (void)st0;
        js += std::string(first ? "" : ", ") + "\"" + op + "\": {\"median\": [";
        first = false;
        std::string mn, mx;
        for (std::size_t i = 0; i < costs.size(); ++i) {
            const Stats& st = costs[i].at(op);
            char b[64];
            std::snprintf(b, sizeof b, "%s%.3f", i ? ", " : "", st.median);
            js += b;
            std::snprintf(b, sizeof b, "%s%.3f", i ? ", " : "", st.min);
            mn += b;
            std::snprintf(b, sizeof b, "%s%.3f", i ? ", " : "", st.max);
            mx += b;
        }
        js += "], \"min\": [" + mn + "], \"max\": [" + mx + "]}";
    }
    js += "}}\n";
    s.write_data("scaling_tasks", js);

    double worst = 0;
    std::string worst_op, detail;
    for (const auto& [op, st0] : costs[0]) {
        const double r = costs.back().at(op).median / st0.median;
        char b[160];
        std::snprintf(b, sizeof b, "%s%s %s -> %s (%.2fx)", detail.empty() ? "" : "; ", op.c_str(),
                      kb::fmt_ns(st0.median).c_str(), kb::fmt_ns(costs.back().at(op).median).c_str(), r);
        detail += b;
        if (op == "muf_periodic_spawn_destroy") continue;
        if (r > worst) {
            worst = r;
            worst_op = op;
        }
    }
    s.emit("sched_ops_10k_over_10",
           kb::pinned(s) + ", FIXED policy, cpu_accounting 1; N ready tasks that never run "
                           "under a priority-50 driver; value = the worst ratio (" + worst_op +
               ") of cost with 10,000 over cost with 10, over set_priority, yield, v_wake_round, "
               "spawn_destroy (ready-heap operations). Medians, 10 -> 10,000: " + detail +
               " (MUF periodic admission updates the critical set incrementally, O(log N): not "
               "counted in the value, plotted in scaling_tasks.png)",
           worst);
}
CHM_BENCH_MEASUREMENT(sched_scaling, "sched_ops_10k_over_10");

}  // namespace
}  // namespace chm::bench
