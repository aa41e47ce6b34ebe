// The soak's servo controller (servo_main.c, modlog.h) seen from the
// driver: the variables and the cycle log it needs, its process (killed,
// stopped and restarted by the chaos: servo_chaos.cpp), its end, and the
// checks on what it and its modules did.
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include "chimera/shm.h"
#include "chimera/svar.h"
#include "soak.hpp"

namespace soak {

namespace {
std::string num(uint64_t v) { return std::to_string(v); }
const char* call_name(uint32_t c) {
    static const char* const n[SOAK_SV_CALLS] = {"none", "take", "spawn", "status", "switch", "kill"};
    return c < SOAK_SV_CALLS ? n[c] : "?";
}
}  // namespace

// soak.hand, soak.solo and the cycle log soak.mlog; 0 or a status.
int Driver::servo_objects() {
    if (opt_.rtpus < SOAK_MOD_ROLES) return 0;  // the controller needs RTPUs 1..3
    for (const char* name : {"soak.hand", "soak.solo"}) {
        chm_svar_decl_t d{name, CHM_SVAR_DOUBLE, SOAK_HAND_ELEMS, 1, "cycle"};
        if (int r = chm_svar_declare(&d)) return r;
    }
    void* p = nullptr;
    if (int r = chm_shm_create("soak.mlog", sizeof(soak_modlog_t), CHM_SHM_COMMON, &p)) return r;
    mlog_ = static_cast<soak_modlog_t*>(p);
    mlog_->base_k = now_ns() / SOAK_MOD_PERIOD_NS;
    return 0;
}

// The next incarnation: it carries on from the ledger (servo_main.c).
// `fault`: a stop point of chm_servo_switch where it is to kill itself
// (CHIMERA_FAULT_AT=<fault>:kill, the first time it passes it), or none.
void Driver::start_servo(const char* fault) {
    if (!mlog_) return;
    __atomic_store_n(&led_->servo.call, uint32_t(SOAK_SV_IDLE), __ATOMIC_SEQ_CST);
    __atomic_store_n(&led_->servo.inc, led_->servo.inc + 1, __ATOMIC_SEQ_CST);
    const std::string log = dir_ + "/servo.log";
    servo_fault_ = fault ? fault : "";
    // Its environment, made before the fork: ours without CHIMERA_FAULT_AT
    // and CHIMERA_STOP_AT, then the point.
    std::vector<std::string> env;
    for (char** e = environ; *e; ++e)
        if (std::strncmp(*e, "CHIMERA_FAULT_AT=", 17) && std::strncmp(*e, "CHIMERA_STOP_AT=", 16)) env.push_back(*e);
    if (fault) env.push_back(std::string("CHIMERA_FAULT_AT=") + fault + ":kill");
    std::vector<char*> envp;
    for (std::string& e : env) envp.push_back(e.data());
    envp.push_back(nullptr);
    const std::string seed = std::to_string(opt_.seed);
    std::fflush(nullptr);
    const pid_t parent = getpid();
    const pid_t pid = fork();
    if (pid == 0) {
        prctl(PR_SET_PDEATHSIG, SIGKILL);
        if (getppid() != parent) _exit(127);
        setsid();
        const int fd = open(log.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0600);
        if (fd >= 0) dup2(fd, 1), dup2(fd, 2);
        execle(opt_.servo_bin.c_str(), opt_.servo_bin.c_str(), bp_.c_str(), ledger_path_.c_str(),
               opt_.mod_hand_so.c_str(), opt_.mod_solo_so.c_str(), seed.c_str(), (char*)nullptr, envp.data());
        _exit(127);
    }
    if (pid < 0) failure(std::string("fork for the servo controller: ") + std::strerror(errno));
    servo_.pid = pid;
    servo_.state = pid > 0 ? Proc::Starting : Proc::Down;
    servo_.since = now_ns();
    servo_.due = servo_.since + 1000000000u;  // Down: a failed fork is tried again
}

// The end, while every RTPU is up: it switches its modules off, kills
// them, gives control back and leaves.
void Driver::stop_servo() {
    if (servo_.pid <= 0) return;
    servo_progress("at the end");
    soak_servo_t& s = led_->servo;
    __atomic_store_n(&s.quit, 1u, __ATOMIC_SEQ_CST);
    const uint64_t by = now_ns() + 60000000000ull;
    int st = 0;
    while (waitpid(servo_.pid, &st, WNOHANG) != servo_.pid) {
        if (now_ns() > by) {
            failure(std::string("the servo controller did not end within 60 s of quit (in call ") +
                    call_name(s.call) + ")");
            kill(servo_.pid, SIGKILL);
            waitpid(servo_.pid, &st, 0);
            break;
        }
        nap_ms(5);
    }
    servo_.pid = -1;
    servo_.state = Proc::Down;
    if (!WIFEXITED(st) || WEXITSTATUS(st) != 0)
        failure("the servo controller ended with wait status " + num(unsigned(st)));
    // While every RTPU is still up (check_servo runs after they stopped,
    // which ends any claim): the last incarnation killed every module,
    // those its predecessors spawned included.
    for (const char* name : {"soak.hand", "soak.solo"}) {
        chm_svar_info_t info{};
        if (chm_svar_info(name, &info) == 0 && info.has_writer)
            failure(std::string(name) + " still has a writer after the servo controller (incarnation " +
                    num(s.inc) + ") ended: " + info.writer);
    }
}

// What the controller saw (a switch done somewhere but not everywhere, a
// refused one that changed something, both hand-over modules ON, a torn
// soak.hand, an unexpected status, a call longer than the stall bound) and
// what the cycle log shows: no cycle of soak.hand run by both A and B.
void Driver::check_servo() {
    if (!mlog_) return;
    const soak_servo_t& s = led_->servo;
    const std::string maybe = n_.sv_kills_noting ? " (a controller was killed while writing one down " +
                                                      num(n_.sv_kills_noting) + " times: the text may be an "
                                                      "earlier one's)"
                                                : "";
    if (s.defects) failure(num(s.defects) + " servo defects, the last: " + s.last_defect + maybe);
    // For diagnosis (the directory goes at the end): the controller's log,
    // every switch and every time A and B both showed ON.
    if (const char* keep = std::getenv("SOAK_KEEP_SERVO_LOG"))
        if (std::system(("cp " + dir_ + "/servo.log '" + keep + "'").c_str()) != 0)
            std::fprintf(stderr, "soak: could not copy the servo log to %s\n", keep);
    if (s.errors)
        failure("servo controller: " + num(s.errors) + " unexpected statuses, the last: " + s.last_err_text + maybe);
    if (s.worst_call_ns > bound_ns_)
        failure(std::string("a servo call took ") + num(s.worst_call_ns / 1000000u) + " ms (" +
                call_name(s.worst_call) + "; bound " + num(bound_ns_ / 1000000u) + " ms)");
    if (!s.handovers) failure("the servo controller handed soak.hand over not once");
    uint64_t both = 0, neither = 0, first = ~0ull, last = 0, first_both = 0;
    for (uint64_t i = 0; i < SOAK_MOD_CAP_BITS; ++i) {
        const bool a = mlog_->bits[0][i >> 3] >> (i & 7) & 1, b = mlog_->bits[1][i >> 3] >> (i & 7) & 1;
        if (a && b && !both++) first_both = i;
        if (a || b) {
            if (first == ~0ull) first = i;
            last = i;
        }
    }
    for (uint64_t i = first; first != ~0ull && i <= last; ++i)
        neither += !(mlog_->bits[0][i >> 3] >> (i & 7) & 1) && !(mlog_->bits[1][i >> 3] >> (i & 7) & 1);
    if (both)
        failure(num(both) + " cycles of soak.hand run by both A and B (first: cycle " +
                num(mlog_->base_k + first_both) + ")");
    for (const char* name : {"soak.hand", "soak.solo"}) {
        chm_svar_info_t info{};
        if (chm_svar_info(name, &info) == 0 && info.has_writer)
            failure(std::string(name) + " still has a writer at the end: " + info.writer);
    }
    report_["servo"] = num(s.handovers) + " hand-overs, " + num(s.first_on) + " first switches on, " +
                       num(s.solo_switches) + " solo on/off; refused and retried: " + num(s.refused_late) +
                       " -ETIME, " + num(s.refused_busy) + " busy, " + num(s.refused_gone) +
                       " RTPU or module gone; checked everywhere " + num(s.checked_done) + ", nowhere " +
                       num(s.checked_nothing) + ", could not tell " + num(s.unverifiable) +
                       "; A and B both ON by status, then one OFF within 10 s: " + num(s.both_on_settled);
    report_["servo_modules"] = num(s.spawns) + " spawns, " + num(s.takes) + " takes, " + num(s.dead_seen) +
                               " found DEAD or gone (longest such call " + num(s.dead_seen_worst_ns / 1000000u) +
                               " ms), " + num(s.errors_cleared) + " cleared from ERROR, " + num(s.kills) +
                               " killed at the end; " + num(s.calls) + " calls, the longest " +
                               num(s.worst_call_ns / 1000000u) + " ms (" + call_name(s.worst_call) + ")";
    std::string in;
    for (unsigned c = 0; c < SOAK_SV_CALLS; ++c)
        in += std::string(c ? ", " : "") + call_name(c) + " " + num(n_.sv_kills_in[c]);
    report_["servo_chaos"] =
        "controller kills " + num(n_.sv_kills) + " (aimed at a switch " + num(n_.sv_kills_aimed) +
        "; by itself at servo.switch.prepared " + num(n_.sv_self_killed[0]) + " of " + num(n_.sv_armed[0]) +
        " armed, committed_one " + num(n_.sv_self_killed[1]) + " of " + num(n_.sv_armed[1]) + ", decided " +
        num(n_.sv_self_killed[2]) + " of " + num(n_.sv_armed[2]) + ", their switches found as the protocol says " +
        num(n_.sv_fault_as_promised) + ", not judgeable " + num(n_.sv_fault_unknown) + "; in call: " + in + "; with a switch unchecked " +
        num(n_.sv_kills_pend) + "; while stopped " + num(n_.sv_kills_stopped) + ", while starting " +
        num(n_.sv_kills_starting) + ", while writing a defect down " + num(n_.sv_kills_noting) + "), stops " +
        num(n_.sv_stops) + ", restarts " + num(n_.sv_restarts) + " (" + num(s.inc) + " incarnations; " +
        num(n_.sv_judged) + " up 10 s or more, of them " + num(n_.sv_idle) + " without a switch); restarted: modules found by name " +
        num(s.adopted) + ", takes after restart " + num(s.takes_after_restart) + ", takes refused as held " +
        num(s.take_refused) + "; switches a killed controller left: done everywhere " + num(s.inherited_done) +
        ", nowhere " + num(s.inherited_nothing) + ", could not tell " + num(s.inherited_unverifiable);
    report_["servo_cycles"] = "A " + num(mlog_->cycles[0]) + ", B " + num(mlog_->cycles[1]) + ", S " +
                              num(mlog_->cycles[2]) + "; soak.hand cycles with two writers " + num(both) +
                              ", with none (a dead or stopped RTPU's) " + num(neither) + "; soak.hand reads " +
                              num(s.hand_reads) + ", torn " + num(s.hand_torn);
}

}  // namespace soak
