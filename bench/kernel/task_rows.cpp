// Table 1, task management: create, destroy, change static priority, and
// the spawn performance target: a task spawned, run and ended (task_spawn_run_exit,
// beside pthread create+join and a Boost.Context fiber created, run and
// destroyed), with spawn+destroy of a task that never runs kept apart. Each row is its own timed loop, run by a
// driver task of priority 9 on a kernel in the default configuration
// (aperiodic tasks under MUF are ordered by user priority); the tasks it spawns
// have priority 1, so they are made ready but never run. Timing: the
// harness's method (calibrated runs, median with min–max) on
// CLOCK_MONOTONIC around batches of 200 operations; the untimed half of
// each batch (the destroys of a create batch, ...) is excluded.
#include <vector>

#include "kbench.hpp"

namespace chm::bench {
namespace {

constexpr int kBatch = 200;

void nop(void*) {}
void count_run(void* p) { ++*static_cast<std::uint64_t*>(p); }

void task_rows(Session& s) {
    Session::pin(s.cpu(0));
    kb::Kernel k;
    std::vector<chm_tid_t> ids(kBatch);
    const std::string where = kb::pinned(s) + ", " + kb::kDefaultConfig + ", spawned by a priority-9 task, "
                              "the new tasks (priority 1) never run; 64 KiB stacks from the warm "
                              "stack pool (warm-up runs first)";
    auto spawn_batch = [&] {
        for (auto& id : ids) id = kb::spawn(nop, nullptr, 1);
    };
    auto destroy_batch = [&] {
        for (auto id : ids)
            if (chm_task_destroy(id) != 0) throw std::runtime_error("chm_task_destroy failed");
    };
    std::function<void()> driver = [&] {
        s.time_custom("task_create", where + "; batches of 200 chm_task_spawn, destroyed untimed",
                      [&](std::uint64_t n) {
                          double t = 0;
                          for (std::uint64_t i = 0; i < n; ++i) {
                              const std::uint64_t t0 = mono_ns();
                              spawn_batch();
                              t += double(mono_ns() - t0);
                              destroy_batch();
                          }
                          return t;
                      },
                      kBatch);
        s.time_custom("task_destroy",
                      where + "; batches of 200 chm_task_destroy of ready tasks that never ran "
                              "(stack back to the pool), spawned untimed",
                      [&](std::uint64_t n) {
                          double t = 0;
                          for (std::uint64_t i = 0; i < n; ++i) {
                              spawn_batch();
                              const std::uint64_t t0 = mono_ns();
                              destroy_batch();
                              t += double(mono_ns() - t0);
                          }
                          return t;
                      },
                      kBatch);
        spawn_batch();
        int prio = 2;
        s.time_ops("task_set_priority",
                   where + "; chm_task_set_priority of one of 200 ready tasks to a new value "
                           "(dequeued and re-queued in the ready heap)",
                   [&](std::uint64_t n) {
                       for (std::uint64_t i = 0; i < n; ++i) {
                           const std::size_t j = std::size_t(i % kBatch);
                           if (j == 0) prio = prio == 2 ? 3 : 2;
                           (void)chm_task_set_priority(ids[j], prio);
                       }
                   });
        destroy_batch();
        s.time_ops("task_spawn_destroy_never_runs",
                   where + "; chm_task_spawn then chm_task_destroy of the same task",
                   [&](std::uint64_t n) {
                       for (std::uint64_t i = 0; i < n; ++i)
                           (void)chm_task_destroy(kb::spawn(nop, nullptr, 1));
                   });
        // Like for like with a thread or fiber created, run and ended: the
        // new task (priority 10) preempts the driver at once, runs its empty
        // body and ends by returning; the driver resumes.
        std::uint64_t ran = 0;
        const Stats st = s.time_ops(
            "task_spawn_run_exit",
            kb::pinned(s) + ", " + kb::kDefaultConfig + "; a priority-9 task "
                            "spawns a priority-10 task that runs at once, its body empty, and "
                            "ends by returning (stack back to the warm pool), then the spawner "
                            "resumes: chm_task_spawn + switch in + exit + switch back",
            [&](std::uint64_t n) {
                for (std::uint64_t i = 0; i < n; ++i) kb::spawn(count_run, &ran, 10);
            });
        if (ran == 0) throw std::runtime_error("the spawned tasks never ran");
        s.emit("task_spawn_run_exit_vs_fiber",
               "task_spawn_run_exit's runs, beside a Boost.Context fiber created, run and destroyed",
               st.median, st.min, st.max);
        s.emit("task_spawn_run_exit_vs_clocked_fiber",
               "task_spawn_run_exit's runs, beside the same fiber charging CPU time at its two switches "
               "(cpu_accounting 1, the default, does that at least)",
               st.median, st.min, st.max);
    };
    kb::TaskSpec t;
    t.priority = 9;
    kb::spawn_fn(&driver, t);
    k.run();
}
CHM_BENCH_MEASUREMENT(task_rows, "task_create", "task_destroy", "task_set_priority",
                      "task_spawn_destroy_never_runs", "task_spawn_run_exit",
                      "task_spawn_run_exit_vs_fiber", "task_spawn_run_exit_vs_clocked_fiber");

}  // namespace
}  // namespace chm::bench
