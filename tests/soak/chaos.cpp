// The soak's chaos phase: every 10 ms, bring processes through their
// states (restart the dead, continue the stopped, reap the terminated),
// sample every survivor's heartbeat, and at random instants kill (-9),
// stop (SIGSTOP for a random time) or terminate (SIGTERM: the graceful
// stop protocol, RTPUs only) a random worker.
#include <cerrno>
#include <cstdio>
#include <cstring>

#include <signal.h>
#include <sys/wait.h>

#include "soak.hpp"

namespace soak {

void Driver::chaos_phase() {
    const uint64_t end = t0_ + uint64_t(opt_.seconds) * 1000000000u;
    uint64_t next_print = t0_ + 10000000000u;
    next_action_ = now_ns() + rnd_range(opt_.gap_min_ms, opt_.gap_max_ms) * 1000000u;
    while (now_ns() < end && !g_interrupted) {
        tick(true);
        if (!opt_.quiet && now_ns() >= next_print) {
            next_print += 10000000000u;
            uint64_t sent = 0, recv = 0, pv = 0;
            for (unsigned i = 0; i < led_->workers; ++i) {
                sent += led_->w[i].sends_ok;
                recv += led_->w[i].recvs_ok;
                pv += led_->w[i].p_ok;
            }
            std::printf("soak: %3llu s: kills %llu, stops %llu, terms %llu, restarts %llu; sent %llu, "
                        "received %llu, P/V %llu; worst stall %.1f ms; servo controller kills %llu, stops %llu\n",
                        (unsigned long long)((now_ns() - t0_) / 1000000000u), (unsigned long long)n_.kills,
                        (unsigned long long)n_.stops, (unsigned long long)n_.terms,
                        (unsigned long long)n_.restarts, (unsigned long long)sent, (unsigned long long)recv,
                        (unsigned long long)pv, worst_.ns / 1e6, (unsigned long long)n_.sv_kills,
                        (unsigned long long)n_.sv_stops);
            std::fflush(stdout);
        }
        nap_witness(10);
    }
}

// Sleep, and count what the host added to the sleep as its own stall.
void Driver::nap_witness(unsigned ms) {
    const uint64_t t = now_ns();
    nap_ms(ms);
    const uint64_t slept = now_ns() - t, asked = uint64_t(ms) * 1000000u;
    if (slept > asked + 1000000u) host_stall_ += slept - asked;  // the usual oversleep is no stall
}

// The host stall since `from` (a gap's start), remembering per gap where
// the count stood when it began.
uint64_t Driver::excused(uint64_t& seen_from, uint64_t& host_at, uint64_t from) const {
    if (from != seen_from) {
        seen_from = from;
        host_at = host_stall_;
    }
    return host_stall_ - host_at;
}

// The last line of a worker's log (chimera-rtpu says there why it stopped).
std::string Driver::log_tail(const Proc& p) const {
    std::string last, line;
    if (FILE* f = std::fopen((dir_ + "/worker" + std::to_string(p.id) + ".log").c_str(), "r")) {
        char buf[512];
        while (std::fgets(buf, sizeof buf, f)) last = buf;
        std::fclose(f);
    }
    while (!last.empty() && last.back() == '\n') last.pop_back();
    return last.empty() ? "(empty)" : last;
}

bool Driver::all_started(const Proc& p) const {
    for (unsigned i : p.ids)
        if (__atomic_load_n(&led_->w[i].started, __ATOMIC_SEQ_CST) != led_->w[i].inc) return false;
    return true;
}

// One step of every process's life; chaos: also act when an action is due.
void Driver::tick(bool chaos) {
    const uint64_t now = now_ns();
    if (last_tick_ && now - last_tick_ > worst_tick_gap_) worst_tick_gap_ = now - last_tick_;
    last_tick_ = now;
    for (Proc& p : procs_) {
        int st = 0;
        switch (p.state) {
        case Proc::Down:
            if (now >= p.due) {
                start(p);
                ++n_.restarts;
                // A quarter of the restarts are struck again 0-15 ms in
                // (a start takes a few tens of ms), while the process
                // joins, loads or opens: the join and recovery races.
                if (chaos && rnd() % 4 == 0) strike(p);
            }
            break;
        case Proc::Starting:
        case Proc::Up:
            if (p.state == Proc::Starting && all_started(p)) {
                p.state = Proc::Up;
                p.floor = now;
            }
            if (waitpid(p.pid, &st, WNOHANG) == p.pid) {  // it ended on its own: never expected
                p.pid = -1;
                failure(p.name() + " ended on its own: " +
                        (WIFEXITED(st) ? "exit " + std::to_string(WEXITSTATUS(st))
                                       : std::string("signal ") + strsignal(WTERMSIG(st))) +
                        "; its log ends: " + log_tail(p));
                absorb_death(p);
                p.state = Proc::Down;
                p.due = now + 100000000u;
            } else if (p.state == Proc::Starting && now - p.since > 15000000000ull) {
                failure(p.name() + " did not start within 15 s");
                kill(p.pid, SIGKILL);
                if (reap(p, 5000, &st)) absorb_death(p);
                p.state = Proc::Down;
                p.due = now;
            }
            break;
        case Proc::Stopped:
            if (now >= p.due) {
                kill(p.pid, SIGCONT);
                p.state = p.resume;
                p.floor = now;  // its own gap while stopped is not a stall
            }
            break;
        case Proc::Terminating:
            if (waitpid(p.pid, &st, WNOHANG) == p.pid) {
                p.pid = -1;
                if (!WIFEXITED(st) || WEXITSTATUS(st) != 0)
                    failure(p.name() + " stopped by SIGTERM ended with status " + std::to_string(st));
                absorb_death(p);
                p.state = Proc::Down;
                p.due = now + rnd_range(0, 300) * 1000000u;
            } else if (now - p.since > 10000000000ull) {
                failure(p.name() + " did not stop within 10 s of SIGTERM");
                kill(p.pid, SIGKILL);
                if (reap(p, 5000, &st)) absorb_death(p);
                p.state = Proc::Down;
                p.due = now;
            }
            break;
        }
    }
    watch_stalls();
    watch_servo(chaos);
    if (chaos) watch_objects();
    if (chaos && now >= next_action_) {
        act();
        next_action_ = now_ns() + rnd_range(opt_.gap_min_ms, opt_.gap_max_ms) * 1000000u;
    }
}

// Pick a worker and do one of kill, stop, terminate to it. At most one
// process is stopped at a time and at most two are down (dead, starting or
// terminating) at a time, so traffic never stops; a process still starting
// (joining the backplane, loading its program) may be stopped or killed
// whatever the count, since it is down already.
void Driver::act() {
    unsigned down = 0, stopped = 0;
    for (const Proc& p : procs_) {
        down += p.state == Proc::Down || p.state == Proc::Starting || p.state == Proc::Terminating;
        stopped += p.state == Proc::Stopped;
    }
    std::vector<Proc*> cand;
    for (Proc& p : procs_)
        if (p.state == Proc::Starting || ((p.state == Proc::Up || p.state == Proc::Stopped) && down < 2))
            cand.push_back(&p);
    if (cand.empty()) return;
    Proc& p = *cand[rnd() % cand.size()];
    const uint64_t k = rnd() % 100;
    ++n_.actions;
    if ((p.state == Proc::Up || p.state == Proc::Starting) && !stopped && k < 40) {
        do_stop(p);
    } else if (p.state == Proc::Up && k >= 80) {
        // Graceful: an RTPU leaves with its tasks inside a call (the stop
        // protocol); a host worker ends its operation under way and leaves.
        kill(p.pid, SIGTERM);
        n_.terms_host += !p.rtpu;
        p.state = Proc::Terminating;
        p.since = now_ns();
        p.killed = true;
        ++n_.terms;
    } else {
        do_kill(p);
    }
}

void Driver::strike(Proc& p) {
    nap_ms(unsigned(rnd_range(0, 15)));
    bool stopped = false;
    for (const Proc& o : procs_) stopped |= o.state == Proc::Stopped;
    ++n_.actions;
    if (!stopped && rnd() % 2) do_stop(p);
    else do_kill(p);
}

void Driver::do_stop(Proc& p) {
    kill(p.pid, SIGSTOP);
    n_.stops_starting += p.state == Proc::Starting;
    p.resume = p.state;
    p.state = Proc::Stopped;
    p.due = now_ns() + rnd_range(20, opt_.stop_max_ms) * 1000000u;
    ++n_.stops;
}

void Driver::do_kill(Proc& p) {
    const bool was_stopped = p.state == Proc::Stopped;
    const bool was_starting = p.state == Proc::Starting || (was_stopped && p.resume == Proc::Starting);
    kill(p.pid, SIGKILL);
    int st = 0;
    if (!reap(p, 10000, &st)) {
        failure(p.name() + " (pid " + std::to_string(p.pid) + ") not gone 10 s after SIGKILL");
        return;
    }
    absorb_death(p);
    p.state = Proc::Down;
    p.since = now_ns();
    p.due = p.since + rnd_range(0, 300) * 1000000u;
    p.killed = true;
    ++n_.kills;
    ++(p.rtpu ? n_.kills_rtpu : n_.kills_host);
    n_.kills_stopped += was_stopped;
    n_.kills_starting += was_starting;
}

// A survivor (up, not stopped) must finish an operation at least every
// bound_ns_. Its gap counts from its last heartbeat, or from its start or
// SIGCONT when later.
void Driver::watch_stalls() {
    const uint64_t now = now_ns();
    std::string stopped;
    for (const Proc& p : procs_)
        if (p.state == Proc::Stopped) stopped = p.name();
    for (Proc& p : procs_) {
        if (p.state != Proc::Up) continue;
        for (unsigned id : p.ids) {
        const soak_worker_t& w = led_->w[id];
        const uint64_t hb = __atomic_load_n(&w.hb_ns, __ATOMIC_SEQ_CST);
        const uint64_t from = hb > p.floor ? hb : p.floor;
        if (now <= from) continue;
        const uint64_t gap = now - from, host = excused(seen_from_[id], host_at_[id], from);
        const uint64_t net = gap > host ? gap - host : 0;
        ++n_.stall_samples;
        if (gap > worst_per_worker_[id]) worst_per_worker_[id] = gap;
        if (gap > worst_.ns) worst_ = {gap, id, w.op, stopped};
        if (net > worst_net_) worst_net_ = net;
        // Only a gap spent inside a backplane call can be the runtime's: one
        // between calls (its op none or a pause) is the host not running it.
        const bool in_call = w.op != SOAK_OP_IDLE && w.op != SOAK_OP_PAUSE;
        if (in_call && net > bound_ns_ && stall_reported_[id] != from) {  // each stall once
            stall_reported_[id] = from;
            failure("worker " + std::to_string(id) + " of " + p.name() + " stalled " + std::to_string(gap / 1000000u) +
                    " ms, " + std::to_string(net / 1000000u) + " beyond the host's own stalls (bound " +
                    std::to_string(bound_ns_ / 1000000u) + " ms) in operation " + op_name(w.op) +
                    (stopped.empty() ? "" : ", " + stopped + " stopped"));
        }
        }
    }
}

// Every object must serve someone within the bound: a queue a send or a
// receive, soak.sem a P, soak.shm a write. A worker's own heartbeat would
// not show an object nobody can use any more (a lock never taken over, a
// unit never given back): its calls would all time out in bound.
void Driver::watch_objects() {
    const uint64_t now = now_ns();
    if (!obj_floor_) {
        for (const Proc& p : procs_)
            if (p.state != Proc::Up) return;
        obj_floor_ = now;
    }
    // Express mail needs an RTPU up: none may be (two down, one stopped).
    bool rtpu_up = false;
    for (const Proc& p : procs_) rtpu_up |= p.rtpu && p.state == Proc::Up;
    if (!rtpu_up) mail_floor_ = now;
    for (unsigned k = 0; k < SOAK_OBJECTS; ++k) {
        const uint64_t ok = __atomic_load_n(&led_->ok_ns[k], __ATOMIC_SEQ_CST);
        // Express mail and the state variables (written by RTPU tasks) need an RTPU up.
        const bool needs_rtpu = k == SOAK_OBJ_MAIL || k == SOAK_OBJ_SVAR;
        const uint64_t floor = needs_rtpu && mail_floor_ > obj_floor_ ? mail_floor_ : obj_floor_;
        const uint64_t from = ok > floor ? ok : floor;
        if (now <= from) continue;
        const uint64_t gap = now - from, host = excused(obj_seen_from_[k], obj_host_at_[k], from);
        if (gap > worst_obj_ns_) {
            worst_obj_ns_ = gap;
            worst_obj_ = k;
        }
        if (gap - (gap > host ? host : gap) > bound_ns_ && obj_reported_[k] != from) {
            obj_reported_[k] = from;
            failure(std::string(object_name(k)) + " served nobody for " + std::to_string(gap / 1000000u) +
                    " ms, the host itself stalled " + std::to_string(host / 1000000u) + " ms of it (bound " + std::to_string(bound_ns_ / 1000000u) + " ms)");
        }
    }
}

}  // namespace soak
