// The MUF overload experiment (issue 6 item 4): one task set, its execution
// times scaled from 50 % to 150 % utilisation, run under RM, EDF, MLF and
// MUF on the virtual clock (chm_time_consume: exact and fast). Three tasks
// are marked critical (35 % of the load; 52.5 % at 150 %, so the critical
// set alone is always feasible). Deadlines are firm: a job still running
// at its deadline is dropped (CHM_DL_ABORT_CYCLE) and counted as a miss.
// Over a 2 s horizon (two hyperperiods) every job released before it is
// either met or missed; the counts are checked against the releases.
// Output: the per-step data for docs/bench/muf_overload.png and the rows
// at 150 %.
#include <cstdio>

#include "kbench.hpp"

namespace chm::bench {
namespace {

constexpr std::uint64_t kMs = 1000000;
constexpr std::uint64_t kHorizon = 2000 * kMs;

struct Spec {
    const char* name;
    std::uint64_t period_ms;
    double util;  // at 100 %
    int critical;
};
// Critical tasks have long periods: rate monotonic ranks them last.
constexpr Spec kSet[] = {
    {"t10", 10, 0.10, 0},  {"t20", 20, 0.15, 0},  {"t25", 25, 0.10, 0},  {"t40", 40, 0.15, 0},
    {"c50", 50, 0.10, 1},  {"t100", 100, 0.15, 0}, {"c125", 125, 0.10, 1}, {"c200", 200, 0.15, 1},
};
constexpr int kTasks = int(sizeof kSet / sizeof kSet[0]);

struct Job {
    std::uint64_t period = 0, wcet = 0, met = 0, missed = 0;
};

chm_deadline_action on_miss(const chm_deadline_info_t* info, void* arg) {
    auto* j = static_cast<Job*>(arg);
    if (info->deadline_ns - j->period < kHorizon) ++j->missed;
    return CHM_DL_ABORT_CYCLE;
}

// Restarted from the top after an aborted cycle: all state lives in Job.
void job_body(void* p) {
    auto* j = static_cast<Job*>(p);
    for (;;) {
        const std::uint64_t release = chm_task_cycle_release();
        if (release >= kHorizon) return;
        chm_time_consume(j->wcet);
        ++j->met;  // finished by its deadline (else the handler dropped it)
        chm_task_wait_period();
    }
}

struct Outcome {
    double crit_pct = 0, noncrit_pct = 0;
    std::uint64_t crit_jobs = 0, noncrit_jobs = 0, crit_missed = 0, noncrit_missed = 0;
    bool accounted = true;  // met + missed == releases for every task
};

Outcome run_set(chm_sched_policy policy, double util) {
    Job jobs[kTasks];
    {
        kb::Kernel k({policy, 1, 0, 1});
        for (int i = 0; i < kTasks; ++i) {
            const Spec& sp = kSet[i];
            jobs[i].period = sp.period_ms * kMs;
            jobs[i].wcet = std::uint64_t(double(jobs[i].period) * sp.util * util);
            kb::TaskSpec t;
            t.name = sp.name;
            t.period_ns = jobs[i].period;
            t.wcet_ns = jobs[i].wcet;
            t.critical = sp.critical;
            t.priority = 1;
            t.on_deadline = on_miss;
            t.on_deadline_arg = &jobs[i];
            t.stack = 16 * 1024;
            kb::spawn(job_body, &jobs[i], t);
        }
        k.run();
    }
    Outcome o;
    for (int i = 0; i < kTasks; ++i) {
        const std::uint64_t releases = kHorizon / jobs[i].period;
        if (jobs[i].met + jobs[i].missed != releases) o.accounted = false;
        if (kSet[i].critical) {
            o.crit_jobs += releases;
            o.crit_missed += jobs[i].missed;
        } else {
            o.noncrit_jobs += releases;
            o.noncrit_missed += jobs[i].missed;
        }
    }
    o.crit_pct = 100.0 * double(o.crit_missed) / double(o.crit_jobs);
    o.noncrit_pct = 100.0 * double(o.noncrit_missed) / double(o.noncrit_jobs);
    return o;
}

void muf_overload(Session& s) {
    Session::pin(s.cpu(0));
    struct P {
        chm_sched_policy policy;
        const char* name;
    };
    const P policies[] = {{CHM_SCHED_RM, "rm"}, {CHM_SCHED_EDF, "edf"}, {CHM_SCHED_MLF, "mlf"},
                          {CHM_SCHED_MUF, "muf"}};
    std::vector<double> utils;
    for (int u = 50; u <= 150; u += 10) utils.push_back(u / 100.0);
    std::string js = "{\"utilisation_pct\": [";
    for (std::size_t i = 0; i < utils.size(); ++i)
        js += (i ? ", " : "") + std::to_string(int(utils[i] * 100 + 0.5));
    js += "], \"horizon_ms\": 2000, \"tasks\": [";
    for (int i = 0; i < kTasks; ++i) {
        char b[120];
        std::snprintf(b, sizeof b, "%s{\"name\": \"%s\", \"period_ms\": %llu, \"util_at_100\": %.2f, "
                      "\"critical\": %d}", i ? ", " : "", kSet[i].name,
                      (unsigned long long)kSet[i].period_ms, kSet[i].util, kSet[i].critical);
        js += b;
    }
    js += "], \"policies\": {";
    bool all_accounted = true;
    for (std::size_t p = 0; p < std::size(policies); ++p) {
        std::string crit, non, cm, nm;
        Outcome at150;
        for (std::size_t i = 0; i < utils.size(); ++i) {
            const Outcome o = run_set(policies[p].policy, utils[i]);
            all_accounted = all_accounted && o.accounted;
            char b[64];
            std::snprintf(b, sizeof b, "%s%.3f", i ? ", " : "", o.crit_pct);
            crit += b;
            std::snprintf(b, sizeof b, "%s%.3f", i ? ", " : "", o.noncrit_pct);
            non += b;
            std::snprintf(b, sizeof b, "%s%llu", i ? ", " : "", (unsigned long long)o.crit_missed);
            cm += b;
            std::snprintf(b, sizeof b, "%s%llu", i ? ", " : "", (unsigned long long)o.noncrit_missed);
            nm += b;
            if (i + 1 == utils.size()) at150 = o;
        }
        js += std::string(p ? ", " : "") + "\"" + policies[p].name + "\": {\"critical_miss_pct\": [" +
              crit + "], \"noncritical_miss_pct\": [" + non + "], \"critical_missed\": [" + cm +
              "], \"noncritical_missed\": [" + nm + "]}";
        char cfg[420];
        std::snprintf(cfg, sizeof cfg,
                      "virtual clock, policy %s, 8 periodic tasks (10-200 ms) scaled to 150 %% "
                      "utilisation, 3 marked critical (52.5 %% of the CPU); firm deadlines (late "
                      "job dropped); 2 s horizon; %llu of %llu critical and %llu of %llu "
                      "non-critical jobs missed; full ramp 50-150 %% in muf_overload.png",
                      policies[p].name, (unsigned long long)at150.crit_missed,
                      (unsigned long long)at150.crit_jobs, (unsigned long long)at150.noncrit_missed,
                      (unsigned long long)at150.noncrit_jobs);
        s.emit(std::string("overload_critical_miss_pct_150_") + policies[p].name, cfg, at150.crit_pct);
        s.emit(std::string("overload_noncritical_miss_pct_150_") + policies[p].name, cfg,
               at150.noncrit_pct);
    }
    js += "}, \"every_job_accounted\": " + std::string(all_accounted ? "true" : "false") + "}\n";
    s.write_data("muf_overload", js);
    if (!all_accounted)
        throw std::runtime_error("a job was neither met nor missed: the experiment's accounting failed");
}
CHM_BENCH_MEASUREMENT(muf_overload, "overload_critical_miss_pct_150_rm",
                      "overload_noncritical_miss_pct_150_rm", "overload_critical_miss_pct_150_edf",
                      "overload_noncritical_miss_pct_150_edf", "overload_critical_miss_pct_150_mlf",
                      "overload_noncritical_miss_pct_150_mlf", "overload_critical_miss_pct_150_muf",
                      "overload_noncritical_miss_pct_150_muf");

}  // namespace
}  // namespace chm::bench
