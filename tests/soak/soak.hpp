// The chaos soak's driver (docs/backplane.md, "Chaos soak"): shared state
// of main.cpp (setup and report), procs.cpp (worker processes), chaos.cpp
// (the random kills, stops and restarts, and the stall watch) and
// finish.cpp (the orderly end and every check).
#pragma once

#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <sys/types.h>

#include "chimera/msgq.h"
#include "chimera/rsem.h"

extern "C" {
#include "ledger.h"
#include "modlog.h"
#include "worker.h"
}

namespace soak {

struct Options {
    unsigned seconds = 600;
    uint64_t seed = 0;         // 0: from the clock (printed either way)
    unsigned rtpus = 3, hosts = 2;
    unsigned sem_units = 2;
    unsigned stop_max_ms = 1000;  // longest SIGSTOP
    unsigned slack_ms = 5000;     // scheduling allowance of the stall bound (loaded shared host)
    unsigned gap_min_ms = 100, gap_max_ms = 500; // between chaos actions
    // Between chaos actions on the servo controller (a kill, or a stop).
    unsigned servo_gap_min_ms = 2000, servo_gap_max_ms = 12000;
    bool servo_chaos = true;  // --no-servo-chaos: spare the controller
    int servo_fault = -1;     // --servo-fault N: every incarnation started in the chaos kills itself at point N
    // The programs it runs; meson builds the paths in (soak/meson.build).
    std::string rtpu_bin = SOAK_RTPU_BIN, host_bin = SOAK_HOST_BIN, worker_so = SOAK_WORKER_SO,
                bpcheck_bin = SOAK_BPCHECK_BIN, servo_bin = SOAK_SERVO_BIN, mod_hand_so = SOAK_MOD_HAND_SO,
                mod_solo_so = SOAK_MOD_SOLO_SO;
    bool quiet = false;
};

// A worker process: an RTPU running worker.c in two tasks, or a host process
// running it once.
struct Proc {
    enum State { Down, Starting, Up, Stopped, Terminating };
    unsigned id = 0;              // its first worker (and its log's name)
    std::vector<unsigned> ids;    // every worker it runs: an RTPU runs two tasks
    int rtpu = 0;         // RTPU number (1..), 0 for a host
    pid_t pid = -1;
    State state = Down;
    State resume = Up;    // Stopped: the state SIGCONT returns it to (Up or Starting)
    uint64_t since = 0;   // when it entered `state`
    uint64_t floor = 0;   // heartbeats before this do not count (start, SIGCONT)
    uint64_t due = 0;     // Down: restart time; Stopped: SIGCONT time
    bool killed = false;  // we sent SIGKILL or SIGTERM: its end is expected
    std::string name() const;
};

struct Counts {
    uint64_t kills = 0, kills_rtpu = 0, kills_host = 0, kills_stopped = 0, kills_starting = 0;
    uint64_t terms = 0, terms_host = 0, stops = 0, stops_starting = 0, restarts = 0, actions = 0;
    uint64_t units_returned = 0, sem_doubt = 0, shm_doubt = 0, dead_bufs_partial = 0;
    uint64_t svar_doubt[SOAK_SVAR_MAX + 1] = {};  // per soak.vr: writes a death left in doubt
    uint64_t stall_samples = 0;
    // The servo controller: kills (by the call it was in: enum
    // soak_servo_call), with a switch unchecked, while stopped or starting,
    // while it wrote a defect down; stops; restarts; incarnations up long
    // enough to be judged (each must switch something).
    uint64_t sv_kills = 0, sv_kills_in[SOAK_SV_CALLS] = {}, sv_kills_pend = 0, sv_kills_stopped = 0;
    uint64_t sv_kills_starting = 0, sv_kills_noting = 0, sv_stops = 0, sv_restarts = 0, sv_judged = 0;
    uint64_t sv_kills_aimed = 0;  // kills that waited for a switch under way
    // Incarnations started to kill themselves at a stop point inside
    // chm_servo_switch (servo_chaos.cpp: kServoFaults), and those that did.
    uint64_t sv_armed[3] = {}, sv_self_killed[3] = {};
    uint64_t sv_fault_as_promised = 0, sv_fault_unknown = 0;  // their switches, as the successor found them
    uint64_t sv_idle = 0;         // incarnations judged that switched nothing (each a failure)
};

// The worst stall one survivor showed, and what it was doing.
struct Stall {
    uint64_t ns = 0;
    unsigned worker = 0;
    uint32_t op = 0;
    std::string peer_stopped;  // the process stopped meanwhile, if any
};

class Driver {
public:
    explicit Driver(Options o) : opt_(std::move(o)) {}
    int run();  // the whole soak; 0 when every check held

    // procs.cpp
    void start(Proc& p);
    bool reap(Proc& p, int timeout_ms, int* status);
    void absorb_death(Proc& p);
    void absorb_worker(const Proc& p, unsigned id);
    std::vector<pid_t> leftover_processes() const;

    // chaos.cpp
    void chaos_phase();
    void tick(bool chaos);
    void act();
    void strike(Proc& p);
    void do_stop(Proc& p);
    void do_kill(Proc& p);
    void watch_stalls();
    void nap_witness(unsigned ms);
    uint64_t excused(uint64_t& seen_from, uint64_t& host_at, uint64_t from) const;
    bool all_started(const Proc& p) const;
    std::string log_tail(const Proc& p) const;
    void watch_objects();

    // servo.cpp
    int servo_objects();
    void start_servo(const char* fault = nullptr);
    void stop_servo();
    void check_servo();
    // servo_chaos.cpp
    void watch_servo(bool chaos);
    void servo_kill();
    void servo_dead(bool stopped, bool starting);
    void servo_expected();
    void servo_stop();
    void servo_progress(const std::string& when);
    bool servo_up() const { return !mlog_ || servo_.state == Proc::Up; }
    uint64_t srnd();

    // finish.cpp
    void finish();
    void abandon();
    void quiesce();
    void drain_and_account();
    void check_sem_and_shm();
    void check_svars();
    void check_file_and_leftovers();

    void failure(const std::string& what);
    uint64_t rnd();
    uint64_t rnd_range(uint64_t lo, uint64_t hi) { return lo + rnd() % (hi - lo + 1); }

    Options opt_;
    std::string dir_, bp_, ledger_path_;
    soak_ledger_t* led_ = nullptr;
    std::vector<Proc> procs_;
    chm_msgq_t* q_[SOAK_QUEUES] = {};
    chm_rsem_t* sem_ = nullptr;
    soak_shm_t* shm_ = nullptr;
    soak_modlog_t* mlog_ = nullptr;  // null: no servo controller (fewer than 3 RTPUs)
    Proc servo_;  // the controller's process: Down, Starting, Up or Stopped; floor: when it was up
    uint64_t srng_ = 0, servo_next_ = 0;  // its own random sequence (from the seed) and next action
    std::string servo_fault_;  // the stop point its incarnation kills itself at, if any
    int sv_expect_ = -1;       // the stop point the last one died at, its switch not yet verified
    uint64_t sv_inh_[3] = {};  // the successor's inherited_* counts then
    uint64_t rng_ = 0, t0_ = 0, next_action_ = 0, last_tick_ = 0, worst_tick_gap_ = 0;
    uint64_t bound_ns_ = 0;
    Counts n_;
    Stall worst_;
    // Objects (SOAK_OBJ_*): each must do its job (a message in or out, a
    // P, a write) within the bound, from the moment every worker was first up.
    uint64_t obj_floor_ = 0, worst_obj_ns_ = 0, mail_floor_ = 0;
    unsigned worst_obj_ = 0;
    uint64_t obj_reported_[SOAK_OBJECTS] = {};
    std::vector<uint64_t> worst_per_worker_;
    std::vector<uint64_t> stall_reported_;   // per worker: the heartbeat whose overlong gap was reported
    // The host's own stalls, as the driver's naps overslept them (a
    // witness that makes no backplane call): a survivor's gap counts
    // against the bound less the host stall that fell inside it.
    uint64_t host_stall_ = 0, worst_net_ = 0;
    std::vector<uint64_t> seen_from_, host_at_;                       // per worker
    uint64_t obj_seen_from_[SOAK_OBJECTS] = {}, obj_host_at_[SOAK_OBJECTS] = {};
    std::vector<std::set<uint32_t>> doubt_;  // per sender: sequences whose send a death left in doubt
    std::vector<soak_msg_t> dead_bufs_;      // complete messages found in dead receivers' buffers
    std::vector<std::string> failures_;
    std::map<std::string, std::string> report_;  // key = value lines of the summary
};

uint64_t now_ns();
extern volatile int g_interrupted;  // SIGINT, SIGTERM or SIGHUP arrived: clean up and fail
inline const char* object_name(unsigned k) {
    static const char* const names[SOAK_OBJECTS] = {"soak.q0",  "soak.q1",      "soak.q2",
                                                    "soak.sem", "soak.shm",     "express mail",
                                                    "soak.v*"};
    return k < SOAK_OBJECTS ? names[k] : "?";
}
inline const char* op_name(uint32_t op) {
    static const char* const names[SOAK_OP_COUNT] = {"none",     "send",     "receive", "P/V",
                                                     "shm write", "shm read", "pause",   "ping",
                                                     "svar write", "svar read"};
    return op < SOAK_OP_COUNT ? names[op] : "?";
}
void nap_ms(unsigned ms);

}  // namespace soak
