// The chaos on the soak's servo controller (docs/backplane.md, "Chaos
// soak"): at random instants, from its own random sequence (drawn from the
// seed), SIGKILL it (the next incarnation starts 50 ms to 1 s later and
// carries on from the ledger: servo_main.c, servo_inherit.c) or SIGSTOP it
// for up to the longest stop. Half the kills are aimed at a switch: the
// kill lands 0-1 ms after the controller enters chm_servo_switch (prepare,
// commit, decision or resolve under way), which a kill at a random instant
// rarely does (a switch is a few ms of a step of 20-100 ms). And half the
// incarnations started during the chaos kill themselves at one of the
// stop points of chm_servo_switch (CHIMERA_FAULT_AT=<point>:kill): after
// prepare (nothing armed), after one part's commit (the decision cell
// open: at T the parties abort it), after the decision (committed, no part
// told: at T they act) - the instants a kill from outside cannot aim at. An incarnation up 10 s or more (stops not
// counted) must have switched something by its end: one that cannot (its
// RTPUs' control not taken again, or refused it) shows here.
#include <cerrno>
#include <cstring>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include "soak.hpp"

namespace soak {

namespace {
constexpr uint64_t kJudgedNs = 10000000000ull;  // an incarnation up this long must have switched
// A controller killed after it decided a switch (cell COMMITTED) and
// before it freed the cell leaves the cell taken for the life of the file
// (docs/architecture.md); 64 of them refuse every switch. One killed with
// its cell still open does not: the next switch short of cells gives it
// back. Past this many kills inside a switch the chaos neither aims kills
// at switches (they may land after the decision) nor arms the point past it.
constexpr uint64_t kCellKillsMax = 40;
const char* const kServoFaults[3] = {"servo.switch.prepared", "servo.switch.committed_one", "servo.switch.decided"};
template <class T>
T ld(const T& v) { return __atomic_load_n(&v, __ATOMIC_SEQ_CST); }
}  // namespace

uint64_t Driver::srnd() {  // xorshift64*, seeded apart from rnd(): the workers' chaos stays as it was
    if (!srng_) srng_ = (opt_.seed ^ 0xD1B54A32D192ED03ull) * 0x9E3779B97F4A7C15ull | 1u;
    srng_ ^= srng_ >> 12;
    srng_ ^= srng_ << 25;
    srng_ ^= srng_ >> 27;
    return srng_ * 2685821657736338717ull;
}

// Every tick: restart, continue, see it up; chaos: act when due.
void Driver::watch_servo(bool chaos) {
    if (!mlog_) return;
    const soak_servo_t& s = led_->servo;
    const uint64_t now = now_ns();
    if (servo_.state == Proc::Down) {
        if (now >= servo_.due) {
            unsigned f = chaos && opt_.servo_chaos && srnd() % 2 ? unsigned(srnd() % 3) : 3u;
            if (chaos && opt_.servo_chaos && opt_.servo_fault >= 0) f = unsigned(opt_.servo_fault);
            if (f == 2) f = n_.sv_kills_in[SOAK_SV_SWITCH] < kCellKillsMax ? f : 0;
            start_servo(f < 3 ? kServoFaults[f] : nullptr);
            if (f < 3) ++n_.sv_armed[f];
            ++n_.sv_restarts;
        }
        return;
    }
    if (servo_.state == Proc::Stopped && now >= servo_.due) {
        kill(servo_.pid, SIGCONT);
        servo_.state = servo_.resume;
        servo_.floor += now - servo_.since;  // its stop is no time it had to switch in
    }
    if (servo_.state == Proc::Starting && ld(s.started) == ld(s.inc)) {
        servo_.state = Proc::Up;
        servo_.floor = now;
        servo_expected();
    }
    int st = 0;
    if (servo_.pid > 0 && waitpid(servo_.pid, &st, WNOHANG) == servo_.pid) {
        if (!servo_fault_.empty() && WIFSIGNALED(st) && WTERMSIG(st) == SIGKILL) {  // at its stop point
            for (unsigned f = 0; f < 3; ++f)
                if (servo_fault_ == kServoFaults[f]) {
                    ++n_.sv_self_killed[f];
                    // What the switch must be found: committed (decided),
                    // or still open, so aborted by the parties at T.
                    sv_expect_ = int(f);
                    sv_inh_[0] = ld(s.inherited_done);
                    sv_inh_[1] = ld(s.inherited_nothing);
                    sv_inh_[2] = ld(s.inherited_unverifiable);
                }
            servo_dead(false, false);
            return;
        }
        servo_.pid = -1;  // never on its own otherwise
        failure("the servo controller (incarnation " + std::to_string(s.inc) + ") ended on its own, wait status " +
                std::to_string(unsigned(st)) + " (" + dir_ + "/servo.log)");
        servo_.state = Proc::Down;
        servo_.due = now + 1000000000u;
        return;
    }
    if (!servo_next_) servo_next_ = now + srnd() % 1000 * 1000000u + opt_.servo_gap_min_ms * 1000000ull;
    if (!chaos || !opt_.servo_chaos || now < servo_next_ || servo_.pid <= 0) return;
    servo_next_ = now + (opt_.servo_gap_min_ms + srnd() % (opt_.servo_gap_max_ms - opt_.servo_gap_min_ms + 1)) *
                            1000000ull;
    if (servo_.state != Proc::Stopped && srnd() % 100 < 35) {
        servo_stop();
        return;
    }
    if (servo_.state == Proc::Up && srnd() % 2 && n_.sv_kills_in[SOAK_SV_SWITCH] < kCellKillsMax) {
        // aimed: wait (up to 500 ms) for a switch under way
        const uint64_t by = now + 500000000u, lag = srnd() % 1001 * 1000u;
        while (ld(s.call) != SOAK_SV_SWITCH && now_ns() < by) usleep(20);
        if (ld(s.call) == SOAK_SV_SWITCH) {
            ++n_.sv_kills_aimed;
            for (const uint64_t at = now_ns() + lag; now_ns() < at;) usleep(20);
        }
    }
    servo_kill();
}

void Driver::servo_stop() {
    kill(servo_.pid, SIGSTOP);
    servo_.resume = servo_.state;
    servo_.state = Proc::Stopped;
    servo_.since = now_ns();
    servo_.due = servo_.since + (20 + srnd() % (opt_.stop_max_ms - 20 + 1)) * 1000000ull;
    ++n_.sv_stops;
}

void Driver::servo_kill() {
    const bool stopped = servo_.state == Proc::Stopped;
    const bool starting = servo_.state == Proc::Starting || (stopped && servo_.resume == Proc::Starting);
    if (stopped) servo_.floor += now_ns() - servo_.since;
    kill(servo_.pid, SIGKILL);
    int st = 0;
    const uint64_t by = now_ns() + 10000000000ull;
    while (waitpid(servo_.pid, &st, WNOHANG) != servo_.pid) {
        if (now_ns() > by) {
            failure("the servo controller (pid " + std::to_string(servo_.pid) + ") not gone 10 s after SIGKILL");
            return;
        }
        nap_ms(1);
    }
    servo_dead(stopped, starting);
}

// It is gone, killed: what it was doing (the call under way, a switch
// whose outcome it had not checked: its successor verifies it, a defect
// half written down), and its successor due.
void Driver::servo_dead(bool stopped, bool starting) {
    soak_servo_t& s = led_->servo;
    const uint32_t call = ld(s.call);
    ++n_.sv_kills_in[call < SOAK_SV_CALLS ? call : 0];
    n_.sv_kills_pend += ld(s.pend.phase) != 0;
    if (ld(s.noting)) {
        ++n_.sv_kills_noting;
        __atomic_store_n(&s.noting, 0u, __ATOMIC_SEQ_CST);
    }
    if (!starting) servo_progress("when killed");
    servo_.pid = -1;
    servo_.state = Proc::Down;
    servo_.since = now_ns();
    servo_.due = servo_.since + (50 + srnd() % 951) * 1000000ull;
    ++n_.sv_kills;
    n_.sv_kills_stopped += stopped;
    n_.sv_kills_starting += starting;
}

// A successor is up: it verified the switch its predecessor killed itself
// in (at kServoFaults[sv_expect_]); the servo protocol says which outcome.
void Driver::servo_expected() {
    if (sv_expect_ < 0) return;
    const soak_servo_t& s = led_->servo;
    const uint64_t done = ld(s.inherited_done) - sv_inh_[0], nothing = ld(s.inherited_nothing) - sv_inh_[1],
                   unknown = ld(s.inherited_unverifiable) - sv_inh_[2];
    if (!done && !nothing && !unknown) return;  // not verified yet (that incarnation was killed first)
    const bool decided = sv_expect_ == 2;
    if (unknown) ++n_.sv_fault_unknown;
    else if (decided ? done : nothing) ++n_.sv_fault_as_promised;
    else
        failure(std::string("the switch a controller died in at ") + kServoFaults[sv_expect_] + " was found done " +
                (done ? "everywhere" : "nowhere") + ", but the cell was " +
                (decided ? "committed (done everywhere at T)" : "open (aborted at T: nothing)") + " (" + dir_ +
                "/servo.log)");
    sv_expect_ = -1;
}

// The incarnation now ending was up kJudgedNs or more: it must have
// switched something (a hand-over, a solo on/off or a first switch on).
void Driver::servo_progress(const std::string& when) {
    const soak_servo_t& s = led_->servo;
    const bool up = servo_.state == Proc::Up || (servo_.state == Proc::Stopped && servo_.resume == Proc::Up);
    if (!up) return;
    const uint64_t now = now_ns(), ran = now - servo_.floor - (servo_.state == Proc::Stopped ? now - servo_.since : 0);
    if (ran < kJudgedNs) return;
    ++n_.sv_judged;
    if (ld(s.switched_inc) != ld(s.inc) && ++n_.sv_idle)
        failure("servo controller incarnation " + std::to_string(s.inc) + " was up " + std::to_string(ran / 1000000u) +
                " ms " + when + " and no switch of it returned 0 (takes after restart so far " +
                std::to_string(s.takes_after_restart) + ", takes refused as held " + std::to_string(s.take_refused) +
                "; " + dir_ + "/servo.log)");
}

}  // namespace soak
