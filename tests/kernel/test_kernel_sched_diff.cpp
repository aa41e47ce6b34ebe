// Differential test of the built-in schedulers: thousands of random task
// sets run through the public C API on the virtual clock, each compared
// with the independent reference simulator (sched_reference.hpp): per task
// the misses and every job's completion time, and the whole timeline (who
// held the CPU when). Jobs are consumed whole and in random slices; the
// slicing must never change the outcome.
//
// CHM_DIFF_SETS sets the number of sets per policy (meson sets it smaller
// under qemu); CHM_DIFF_SEED the seed (0 = random, printed). A failing set
// is printed as a C++ initialiser to paste into kRegressions below.
#include <cinttypes>
#include <cstdio>
#include <array>
#include <cstdlib>
#include <random>
#include <sstream>

#include "kernel.hpp"
#include "kernel_fixture.hpp"
#include "sched_reference.hpp"

namespace chm::test {
namespace {

constexpr std::uint64_t kUnit = 50 * kUs;  // every period, deadline, work and phase is a multiple

struct Case {
    chm_sched_policy policy;
    std::uint64_t quantum;
    std::vector<ref::Task> tasks;
};

// A case as the initialiser of kRegressions (times in units of kUnit).
std::string describe(const Case& c) {
    static const char* names[] = {"CHM_SCHED_MUF", "CHM_SCHED_RM", "CHM_SCHED_EDF", "CHM_SCHED_MLF",
                                  "CHM_SCHED_FIXED"};
    std::ostringstream o;
    o << "{\"\", " << names[c.policy] << ", " << c.quantum / kUnit << ", {\n";
    for (const auto& t : c.tasks)
        o << "    {" << t.period / kUnit << ", " << t.deadline / kUnit << ", " << t.wcet / kUnit << ", "
          << t.work / kUnit << ", " << t.phase / kUnit << ", " << t.priority << ", "
          << (t.critical ? "true" : "false") << ", " << t.jobs << "},\n";
    o << "}},";
    return o.str();
}

// Sets that once differed, in units of kUnit: period, deadline, wcet,
// work, phase, priority, critical, jobs.
struct Regression {
    const char* what;
    chm_sched_policy policy;
    std::uint64_t quantum;
    std::vector<std::array<std::uint64_t, 8>> tasks;
};
const Regression kRegressions[] = {
    // A's work ends at its deadline (4) as B, more urgent under RM, is
    // released: A is on time. The kernel used to preempt A inside its last
    // chm_time_consume and count a miss when it got back to wait_period.
    {"completes at its deadline as a release preempts", CHM_SCHED_RM, 0, {
        {10, 4, 4, 4, 0, 0, false, 2},
        {5, 5, 1, 1, 4, 0, false, 2},
    }},
    // The first set the differential test found against the old kernel.
    {"random RM set 0 of seed 20261125", CHM_SCHED_RM, 31, {
        {104, 95, 13, 13, 0, 1, false, 7},
        {60, 48, 8, 8, 0, 2, false, 12},
        {185, 166, 19, 19, 0, 2, false, 4},
        {181, 114, 17, 17, 0, 0, false, 4},
        {93, 52, 14, 14, 0, 2, false, 7},
    }},
};

Case case_of(const Regression& r) {
    Case c{r.policy, r.quantum * kUnit, {}};
    for (const auto& v : r.tasks)
        c.tasks.push_back(ref::Task{v[0] * kUnit, v[1] * kUnit, v[2] * kUnit, v[3] * kUnit, v[4] * kUnit,
                                    int(v[5]), v[6] != 0, int(v[7])});
    return c;
}

Case random_case(std::mt19937_64& rng, chm_sched_policy policy) {
    auto pick = [&](std::uint64_t lo, std::uint64_t hi) {  // inclusive
        return std::uniform_int_distribution<std::uint64_t>(lo, hi)(rng);
    };
    Case c{policy, pick(0, 1) ? kUnit * pick(2, 40) : 0, {}};
    const int n = int(pick(2, 8));
    const double total_u = 0.5 + 1.1 * std::uniform_real_distribution<double>(0, 1)(rng);
    std::vector<double> w(n);
    double wsum = 0;
    for (double& x : w) wsum += (x = 0.2 + std::uniform_real_distribution<double>(0, 1)(rng));
    std::uint64_t longest = 0;
    for (int i = 0; i < n; ++i) {
        ref::Task t;
        t.period = kUnit * pick(10, 200);  // 0.5 .. 10 ms
        t.deadline = kUnit * pick(t.period / kUnit / 2, t.period / kUnit);
        const auto want = std::uint64_t(total_u * w[i] / wsum * double(t.period) / double(kUnit));
        t.wcet = kUnit * std::clamp<std::uint64_t>(want, 1, t.deadline / kUnit);
        t.work = t.wcet;  // the estimate is exact, or under- or overestimated
        if (pick(0, 3) == 0) t.work = kUnit * pick(1, t.wcet / kUnit * 5 / 4 + 1);
        t.phase = pick(0, 1) ? kUnit * pick(0, t.period / kUnit) : 0;
        t.priority = int(pick(0, 2));  // few levels: equal priorities happen
        t.critical = pick(0, 3) == 0;
        longest = std::max(longest, t.period + t.phase);
        c.tasks.push_back(t);
    }
    for (auto& t : c.tasks) {  // about four of the longest periods
        const std::uint64_t horizon = 4 * longest;
        t.jobs = int(std::max<std::uint64_t>(1, (horizon - std::min(horizon, t.phase)) / t.period));
    }
    return c;
}

// ---- the kernel side
struct Run {
    const ref::Task* def;
    bool sliced;
    std::uint64_t slice_seed;
    std::vector<std::uint64_t> completions;
};

std::vector<std::pair<std::uint64_t, int>> g_switches;  // (when, task index or -1)
std::vector<chm_tid_t> g_ids;

void on_switch(const kernel::Tcb* next, std::uint64_t now) {
    int who = -1;
    if (next)
        for (std::size_t i = 0; i < g_ids.size(); ++i)
            if (g_ids[i] == kernel::tid_of(next)) who = int(i);
    g_switches.emplace_back(now, who);
}

void job_body(void* p) {
    Run* r = static_cast<Run*>(p);
    std::mt19937_64 rng(r->slice_seed);
    for (int j = 0; j < r->def->jobs; ++j) {
        std::uint64_t left = r->def->work;
        while (left) {  // random ns amounts: slice ends fall anywhere
            std::uint64_t step = left;
            if (r->sliced) step = std::min(left, 1 + rng() % (2 * kUnit + 7));
            chm_time_consume(step);
            left -= step;
        }
        r->completions.push_back(chm_time_now());
        if (j + 1 < r->def->jobs) {
            ASSERT_EQ(chm_task_wait_period(), 0);
        }
    }
}

chm_deadline_action keep_going(const chm_deadline_info_t*, void*) { return CHM_DL_CONTINUE; }

std::vector<ref::Segment> segments(std::uint64_t end) {
    std::vector<ref::Segment> out;
    std::uint64_t start = 0;
    int who = -1;
    auto close = [&](std::uint64_t t) {
        if (start < t) {
            if (!out.empty() && out.back().task == who) out.back().end = t;
            else out.push_back({start, t, who});
        }
    };
    for (auto [t, next] : g_switches) {
        close(t);
        start = std::max(start, t);
        who = next;
    }
    close(end);
    return out;
}

std::string show(const std::vector<ref::Segment>& v, std::size_t from) {
    std::ostringstream o;
    for (std::size_t i = from; i < v.size() && i < from + 8; ++i)
        o << "[" << v[i].start << "," << v[i].end << ")=" << v[i].task << " ";
    return o.str();
}

struct Totals {
    std::uint64_t jobs = 0, misses = 0, segments = 0, switches = 0;
};
Totals g_totals;

// Runs one case through the kernel; returns "" or what differs.
std::string check(const Case& c, bool sliced, std::uint64_t seed) {
    const ref::Result want = ref::simulate(c.policy, c.quantum, c.tasks);
    for (std::size_t i = 0; i < c.tasks.size(); ++i) {
        g_totals.jobs += want.completions[i].size();
        g_totals.misses += want.misses[i];
    }
    g_totals.segments += want.timeline.size();

    chm_kernel_config_t cfg;
    chm_kernel_config_init(&cfg);
    cfg.policy = c.policy;
    cfg.virtual_clock = 1;
    cfg.quantum_ns = c.quantum;
    if (chm_kernel_init(&cfg) != 0) return "chm_kernel_init failed";
    std::vector<Run> runs;
    runs.reserve(c.tasks.size());
    g_ids.assign(c.tasks.size(), CHM_TID_NONE);
    g_switches.clear();
    kernel::g_k.trace_switch = on_switch;
    for (std::size_t i = 0; i < c.tasks.size(); ++i) {
        const ref::Task& t = c.tasks[i];
        runs.push_back(Run{&t, sliced, seed * 131 + i, {}});
        chm_task_attr_t a;
        chm_task_attr_init(&a);
        a.priority = t.priority;
        a.critical = t.critical;
        a.period_ns = t.period;
        a.deadline_ns = t.deadline;
        a.wcet_ns = t.wcet;
        a.start_ns = t.phase;
        a.on_deadline = keep_going;
        if (chm_task_spawn(&g_ids[i], job_body, &runs.back(), &a) != 0) return "spawn failed";
    }
    const int rc = chm_kernel_run();
    const std::uint64_t end = chm_time_now();
    kernel::g_k.trace_switch = nullptr;
    std::ostringstream diff;
    if (rc != 0) diff << "chm_kernel_run returned " << rc << "\n";
    for (std::size_t i = 0; i < c.tasks.size(); ++i) {
        chm_task_status_t st{};
        if (chm_task_status(g_ids[i], &st) != 0) diff << "task " << i << ": no status after it ended\n";
        else if (st.misses != want.misses[i])
            diff << "task " << i << ": misses " << st.misses << ", reference " << want.misses[i] << "\n";
        if (runs[i].completions != want.completions[i]) {
            std::size_t k = 0;
            while (k < runs[i].completions.size() && k < want.completions[i].size() &&
                   runs[i].completions[k] == want.completions[i][k])
                ++k;
            diff << "task " << i << ": job " << k << " completed at "
                 << (k < runs[i].completions.size() ? std::to_string(runs[i].completions[k]) : "-")
                 << ", reference "
                 << (k < want.completions[i].size() ? std::to_string(want.completions[i][k]) : "-") << "\n";
        }
    }
    g_totals.switches += g_switches.size();
    const auto got = segments(end);
    if (got != want.timeline) {
        std::size_t k = 0;
        while (k < got.size() && k < want.timeline.size() && got[k] == want.timeline[k]) ++k;
        const std::size_t from = k >= 2 ? k - 2 : 0;
        diff << "timeline differs at segment " << k << "\n  kernel:    " << show(got, from)
             << "\n  reference: " << show(want.timeline, from) << "\n";
    }
    chm_kernel_fini();
    return diff.str();
}

class SchedDiff : public ::testing::TestWithParam<chm_sched_policy> {};

TEST_P(SchedDiff, RandomSetsMatchTheReferenceWholeAndSliced) {
    std::uint64_t seed = env_or("CHM_DIFF_SEED", 20261125);
    if (!seed) seed = std::random_device{}() | 1;
    const std::uint64_t sets = env_or("CHM_DIFF_SETS", 1000);
    std::printf("seed %" PRIu64 ", %" PRIu64 " sets\n", seed, sets);
    std::mt19937_64 rng(seed * 7 + std::uint64_t(GetParam()));
    int failures = 0;
    g_totals = Totals{};
    for (std::uint64_t n = 0; n < sets && failures < 3; ++n) {
        const Case c = random_case(rng, GetParam());
        for (bool sliced : {false, true}) {
            const std::string d = check(c, sliced, n);
            if (d.empty()) continue;
            ++failures;
            ADD_FAILURE() << "set " << n << (sliced ? " (sliced)" : " (whole)") << " differs:\n"
                          << d << "paste into kRegressions:\n"
                          << describe(c);
            break;
        }
    }
    std::printf("compared %" PRIu64 " jobs, %" PRIu64 " misses, %" PRIu64 " timeline segments (%" PRIu64
                " kernel switches)\n",
                g_totals.jobs, g_totals.misses, g_totals.segments, g_totals.switches);
    // The sets must exercise what they claim to: overloads that miss, and
    // many decisions.
    EXPECT_GT(g_totals.misses, sets);
    EXPECT_GT(g_totals.segments, 10 * sets);
}

TEST(SchedDiffRegressions, EachMatchesTheReference) {
    for (const Regression& r : kRegressions)
        for (bool sliced : {false, true}) {
            const std::string d = check(case_of(r), sliced, 1);
            EXPECT_EQ(d, "") << r.what << (sliced ? " (sliced)" : " (whole)");
        }
}

TEST(SchedDiffRegressions, AJobDoneAtItsDeadlineIsOnTimeWhoeverIsReleasedThen) {
    const ref::Result r = ref::simulate(CHM_SCHED_RM, 0, case_of(kRegressions[0]).tasks);
    EXPECT_EQ(r.misses[0], 0u);
    EXPECT_EQ(r.completions[0].front(), 4 * kUnit);
}

INSTANTIATE_TEST_SUITE_P(Policies, SchedDiff,
                         ::testing::Values(CHM_SCHED_RM, CHM_SCHED_EDF, CHM_SCHED_MLF, CHM_SCHED_MUF,
                                           CHM_SCHED_FIXED),
                         [](const auto& info) {
                             switch (info.param) {
                             case CHM_SCHED_RM: return std::string("RM");
                             case CHM_SCHED_EDF: return std::string("EDF");
                             case CHM_SCHED_MLF: return std::string("MLF");
                             case CHM_SCHED_FIXED: return std::string("FIXED");
                             default: return std::string("MUF");
                             }
                         });

}  // namespace
}  // namespace chm::test
