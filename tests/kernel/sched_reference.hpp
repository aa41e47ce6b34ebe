// An independent reference for the built-in scheduling policies: an
// event-driven simulator written from the definitions in chimera/sched.h
// ("The schedule, precisely"), sharing no code with the kernel. It is meant
// to be read in one sitting; it is slow on purpose (every decision scans
// every task) and knows nothing of heaps, timers or slices.
//
// Model: periodic tasks, each a fixed number of jobs. Job k of task i is
// released at phase + k*period (or when job k-1 completes, if that is
// later), must do `work` ns of CPU and is due at release + deadline. The
// task ends when its last job completes.
#pragma once

#include <algorithm>
#include <cstdint>
#include <vector>

#include "chimera/kernel.h"

namespace chm::ref {

struct Task {
    std::uint64_t period = 0, deadline = 0, wcet = 0, work = 0, phase = 0;
    int priority = 0;
    bool critical = false;
    int jobs = 1;
};

struct Segment {  // [start, end) on the CPU; task -1 is idle
    std::uint64_t start, end;
    int task;
    bool operator==(const Segment&) const = default;
};

struct Result {
    std::vector<Segment> timeline;
    std::vector<std::vector<std::uint64_t>> completions;  // per task, per job
    std::vector<std::uint64_t> misses;                     // per task
};

inline constexpr std::uint64_t kNever = UINT64_MAX;

class Simulator {
public:
    Simulator(chm_sched_policy policy, std::uint64_t quantum, std::vector<Task> tasks)
        : policy_(policy), quantum_(quantum), def_(std::move(tasks)), st_(def_.size()) {
        res_.completions.resize(def_.size());
        res_.misses.assign(def_.size(), 0);
    }

    Result run() {
        for (std::size_t i = 0; i < def_.size(); ++i) {
            if (def_[i].phase == 0) release(int(i), 0);
            else st_[i].next_release = def_[i].phase;
        }
        decide();
        while (alive()) {
            const std::uint64_t te = next_event();
            advance_to(te);
            // One instant: the running job's work ends first (it is on time
            // when now <= its deadline), then the timers due now — releases
            // in task order, deadlines passing — then the completed task
            // takes its next release, then one decision.
            const int done = (running_ >= 0 && st_[running_].left == 0) ? running_ : -1;
            if (done >= 0) complete(done);
            for (std::size_t i = 0; i < def_.size(); ++i) {
                State& s = st_[i];
                if (s.phase == Phase::WaitRelease && s.next_release == now_ && int(i) != done)
                    release(int(i), now_);
            }
            for (std::size_t i = 0; i < def_.size(); ++i) miss_if_due(int(i));
            if (done >= 0) after_completion(done);
            for (std::size_t i = 0; i < def_.size(); ++i) miss_if_due(int(i));  // a late release's
            decide();
        }
        close_segment();
        return res_;
    }

private:
    enum class Phase { WaitRelease, Ready, Running, Ended };
    struct State {
        Phase phase = Phase::WaitRelease;
        int job = 0;
        std::uint64_t release = 0, abs_deadline = 0, used = 0, left = 0, seq = 0;
        std::uint64_t next_release = 0;
        bool deadline_armed = false;  // the job is not complete; its miss fires at deadline + 1
    };

    bool alive() const {
        return std::any_of(st_.begin(), st_.end(), [](const State& s) { return s.phase != Phase::Ended; });
    }

    void release(int i, std::uint64_t r) {
        State& s = st_[i];
        s.phase = Phase::Ready;
        s.release = r;
        s.abs_deadline = r + def_[i].deadline;
        s.used = 0;
        s.left = def_[i].work;
        s.seq = ++seq_;
        s.deadline_armed = true;
    }

    void miss_if_due(int i) {
        State& s = st_[i];
        if (s.deadline_armed && s.abs_deadline + 1 <= now_) {
            s.deadline_armed = false;
            ++res_.misses[i];
        }
    }

    void complete(int i) {
        State& s = st_[i];
        res_.completions[i].push_back(now_);
        if (s.deadline_armed && now_ > s.abs_deadline) ++res_.misses[i];  // its timer fires now too
        s.deadline_armed = false;
        running_ = -1;
        ++s.job;
        s.phase = Phase::WaitRelease;
        s.next_release = s.release + def_[i].period;
        if (s.job == def_[i].jobs) s.phase = Phase::Ended;  // the task returns: it leaves the set
    }

    void after_completion(int i) {
        State& s = st_[i];
        if (s.phase == Phase::WaitRelease && s.next_release <= now_) release(i, s.next_release);
    }

    std::uint64_t next_event() const {
        std::uint64_t te = kNever;
        if (running_ >= 0) te = now_ + st_[running_].left;
        for (const State& s : st_) {
            if (s.phase == Phase::WaitRelease) te = std::min(te, s.next_release);
            if (s.deadline_armed) te = std::min(te, s.abs_deadline + 1);
        }
        if (running_ >= 0 && quantum_)
            te = std::min(te, slice_start_ + ((now_ - slice_start_) / quantum_ + 1) * quantum_);
        return te;
    }

    void advance_to(std::uint64_t te) {
        if (running_ >= 0) {
            st_[running_].used += te - now_;
            st_[running_].left -= te - now_;
        }
        now_ = te;
    }

    // ---- the policies' order (sched.h)
    bool in_critical_set(int i) const {
        if (def_[i].critical) return true;
        // MUF: user-marked tasks, then the longest prefix of the others in
        // rate order (period, then spawn order) whose utilisation, in parts
        // per billion rounded down, keeps the total <= 1.
        constexpr std::uint64_t kOne = 1000000000ull;
        auto util = [&](int j) { return def_[j].wcet * kOne / def_[j].period; };
        std::uint64_t total = 0;
        std::vector<int> others;
        for (int j = 0; j < int(def_.size()); ++j) {
            if (st_[j].phase == Phase::Ended) continue;
            if (def_[j].critical) total += util(j);
            else others.push_back(j);
        }
        std::stable_sort(others.begin(), others.end(),
                         [&](int a, int b) { return def_[a].period < def_[b].period; });
        for (int j : others) {
            if (total > kOne || total + util(j) > kOne) return false;  // j and all after it are out
            total += util(j);
            if (j == i) return true;
        }
        return false;
    }
    // Laxity plus now (the same "now" for every task at one decision).
    std::int64_t laxity(int i) const {
        const State& s = st_[i];
        const std::uint64_t rem = def_[i].wcet > s.used ? def_[i].wcet - s.used : 0;
        return std::int64_t(s.abs_deadline) - std::int64_t(rem);
    }
    // Policy key, smaller first: (class, value).
    std::pair<std::int64_t, std::int64_t> key(int i) const {
        switch (policy_) {
        case CHM_SCHED_RM: return {0, std::int64_t(def_[i].period)};
        case CHM_SCHED_EDF: return {0, std::int64_t(st_[i].abs_deadline)};
        case CHM_SCHED_MLF: return {0, laxity(i)};
        case CHM_SCHED_MUF: return {in_critical_set(i) ? 0 : 1, laxity(i)};
        default: return {0, 0};
        }
    }
    // Strictly more urgent: the policy's key, then the user priority.
    bool before(int a, int b) const {
        const auto ka = key(a), kb = key(b);
        if (ka != kb) return ka < kb;
        return def_[a].priority > def_[b].priority;
    }
    // The head of the ready set: most urgent, then first come.
    int head() const {
        int h = -1;
        for (int i = 0; i < int(def_.size()); ++i) {
            if (st_[i].phase != Phase::Ready) continue;
            if (h < 0 || before(i, h) || (!before(h, i) && st_[i].seq < st_[h].seq)) h = i;
        }
        return h;
    }

    void decide() {
        const int h = head();
        if (running_ >= 0) {
            const int cur = running_;
            if (h < 0) return;
            if (before(h, cur)) {  // preempted: it keeps its place among equals
                st_[cur].phase = Phase::Ready;
                dispatch(h);
                return;
            }
            const bool expired = quantum_ && now_ > slice_start_ && (now_ - slice_start_) % quantum_ == 0;
            if (!before(cur, h) && expired) {  // round robin: behind its equals
                st_[cur].phase = Phase::Ready;
                st_[cur].seq = ++seq_;
                dispatch(h);
            }
            return;
        }
        if (h >= 0) dispatch(h);
        else if (last_ >= 0) open_segment(-1);
    }

    void dispatch(int i) {
        st_[i].phase = Phase::Running;
        running_ = i;
        // A task that takes the CPU straight back (its own late release)
        // keeps its slice; anyone else starts one.
        if (i != last_ || seg_task_ != i) slice_start_ = now_;
        last_ = i;
        open_segment(i);
    }

    void open_segment(int task) {
        if (task == seg_task_) return;
        close_segment();
        seg_task_ = task;
        seg_start_ = now_;
    }
    void close_segment() {
        if (seg_start_ < now_) {
            if (!res_.timeline.empty() && res_.timeline.back().task == seg_task_)
                res_.timeline.back().end = now_;
            else
                res_.timeline.push_back({seg_start_, now_, seg_task_});
        }
        seg_start_ = now_;
    }

    chm_sched_policy policy_;
    std::uint64_t quantum_;
    std::vector<Task> def_;
    std::vector<State> st_;
    Result res_;
    std::uint64_t now_ = 0, seq_ = 0, slice_start_ = 0, seg_start_ = 0;
    int running_ = -1, last_ = -1, seg_task_ = -1;
};

inline Result simulate(chm_sched_policy policy, std::uint64_t quantum, std::vector<Task> tasks) {
    return Simulator(policy, quantum, std::move(tasks)).run();
}

}  // namespace chm::ref
