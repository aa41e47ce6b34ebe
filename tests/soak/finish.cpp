// The soak's end: an orderly stop of every worker, then the checks —
// message accounting, semaphore units, the seqlock block, the queues, the
// checker on the file at rest, and nothing left behind.
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "../private_dir.hpp"
#include "chimera/bp.h"
#include "chimera/shm.h"
#include "chimera/spin.h"
#include "chimera/svar.h"
#include "soak.hpp"

namespace soak {

namespace {
std::string num(uint64_t v) { return std::to_string(v); }
}  // namespace

void Driver::finish() {
    quiesce();
    drain_and_account();
    check_sem_and_shm();
    check_svars();
    check_servo();
    check_file_and_leftovers();
}

// Interrupted (a signal to the driver, a test's timeout): kill and reap
// every worker, leave, remove the directory; nothing is checked.
void Driver::abandon() {
    for (Proc& p : procs_) {
        int st = 0;
        if (p.pid > 0 && kill(p.pid, SIGKILL) == 0) reap(p, 5000, &st);
    }
    if (servo_.pid > 0 && kill(servo_.pid, SIGKILL) == 0) waitpid(servo_.pid, nullptr, 0);
    (void)!chm_bp_leave();
    chm::test::remove_private_dir(dir_);
    failure("interrupted by a signal: workers killed, " + dir_ + " removed, nothing checked");
}

// Continue the stopped, restart the dead, then tell every worker to quit
// after its operation under way (each gives back what it holds), let the
// hosts leave and stop the RTPUs with SIGTERM. Every wait is bounded.
void Driver::quiesce() {
    const uint64_t up_by = now_ns() + 30000000000ull;
    for (Proc& p : procs_)
        if (p.state == Proc::Stopped) p.due = 0;
    if (servo_.state == Proc::Stopped || servo_.state == Proc::Down) servo_.due = 0;
    for (bool all_up = false; !all_up && now_ns() < up_by; nap_witness(10)) {
        tick(false);
        all_up = servo_up();
        for (const Proc& p : procs_) all_up &= p.state == Proc::Up;
    }
    for (Proc& p : procs_)
        if (p.state != Proc::Up) failure(p.name() + " was not up again 30 s after the chaos ended");
    if (!servo_up()) failure("the servo controller was not up again 30 s after the chaos ended (" + dir_ + "/servo.log)");
    stop_servo();  // while every RTPU is up: its modules off and killed, control given back
    for (unsigned i = 0; i < led_->workers; ++i) __atomic_store_n(&led_->w[i].quit, 1u, __ATOMIC_SEQ_CST);
    const uint64_t done_by = now_ns() + 10000000000ull;
    for (Proc& p : procs_) {
        if (p.state != Proc::Up) continue;
        for (unsigned id : p.ids) {
            const soak_worker_t& w = led_->w[id];
            while (__atomic_load_n(&w.done, __ATOMIC_SEQ_CST) != w.inc && now_ns() < done_by) nap_ms(5);
            if (w.done != w.inc)
                failure("worker " + std::to_string(id) + " of " + p.name() +
                        " did not finish its operation within 10 s of quit (" + op_name(w.op) + ")");
        }
    }
    for (Proc& p : procs_)
        if (p.pid > 0 && p.rtpu) kill(p.pid, SIGTERM);
    for (Proc& p : procs_) {
        if (p.pid <= 0) continue;
        int st = 0;
        if (!reap(p, 10000, &st)) {
            failure(p.name() + " did not end within 10 s at the end of the soak");
            kill(p.pid, SIGKILL);
            reap(p, 5000, &st);
        } else if (!WIFEXITED(st) || WEXITSTATUS(st) != 0) {
            failure(p.name() + " ended with wait status " + num(unsigned(st)) + " at the end of the soak");
        }
        absorb_death(p);
        p.state = Proc::Down;
    }
}

// Empty every queue (the driver is a receiver too), count the messages
// found in dead receivers' buffers that nobody else received, and check
// every sequence number of every sender:
//   sent (its send returned 0)          -> received exactly once
//   not sent (timed out, or never)      -> never received
//   in doubt (the sender died in send)  -> received at most once
void Driver::drain_and_account() {
    uint64_t drained = 0, driver_dups = 0, bad = 0;
    for (chm_msgq_t* q : q_) {
        for (;;) {
            soak_msg_t m{};
            chm_msgq_msg_info_t info;
            const int r = chm_msgq_try_receive(q, &m, sizeof m, &info);
            if (r == -EAGAIN) break;
            if (r < 0) {
                failure("draining a queue: status " + std::to_string(r) + " " + chm_bp_last_error());
                break;
            }
            if (!soak_msg_ok(&m, r, led_->workers)) {
                ++bad;
                continue;
            }
            uint8_t* byte = &soak_recv_bits(led_, m.sender)[m.seq >> 3];
            if (*byte & (1u << (m.seq & 7))) ++driver_dups;
            *byte = uint8_t(*byte | (1u << (m.seq & 7)));
            ++drained;
        }
        chm_msgq_info_t info;
        if (chm_msgq_info(q, &info) == 0 &&
            (info.count || info.receivers_waiting || info.senders_waiting || info.broken))
            failure("a queue after the drain: count " + num(info.count) + ", receivers waiting " +
                    num(info.receivers_waiting) + ", senders waiting " + num(info.senders_waiting) +
                    (info.broken ? ", broken" : ""));
    }
    uint64_t dead_taken = 0;
    for (const soak_msg_t& m : dead_bufs_) {
        uint8_t* byte = &soak_recv_bits(led_, m.sender)[m.seq >> 3];
        if (!(*byte & (1u << (m.seq & 7)))) {
            *byte = uint8_t(*byte | (1u << (m.seq & 7)));
            ++dead_taken;
        }
    }
    uint64_t sent = 0, received = 0, lost = 0, phantom = 0, doubt = 0, doubt_arrived = 0, dups = driver_dups;
    uint64_t v_busy = 0;
    uint64_t torn = 0, bad_w = bad, errors = 0, pv = 0, ping_ok = 0, ping_down = 0, ping_late = 0;
    std::string first_lost, first_phantom;
    for (unsigned s = 0; s < led_->workers; ++s) {
        const soak_worker_t& w = led_->w[s];
        dups += w.dups;
        torn += w.torn;
        bad_w += w.bad_msgs;
        errors += w.errors;
        pv += w.p_ok;
        v_busy += w.v_busy;
        ping_ok += w.pings_ok;
        ping_down += w.pings_down;
        ping_late += w.pings_late;
        if (w.errors)
            failure("worker " + num(s) + ": " + num(w.errors) + " unexpected statuses, the last " +
                    std::to_string(w.last_err) + " in operation " + op_name(w.last_err_op) + ": " +
                    std::string(w.last_err_text, strnlen(w.last_err_text, sizeof w.last_err_text)));
        const uint8_t* sb = soak_sent_bits(led_, s);
        const uint8_t* rb = soak_recv_bits(led_, s);
        for (uint32_t seq = 1; seq <= w.last_seq && seq < SOAK_SEQ_CAP; ++seq) {
            const bool is_sent = soak_bit(sb, seq), is_recv = soak_bit(rb, seq), in_doubt = doubt_[s].count(seq);
            sent += is_sent;
            received += is_recv;
            if (in_doubt) {
                ++doubt;
                doubt_arrived += is_recv;
            } else if (is_sent && !is_recv) {
                if (!lost++) first_lost = num(s) + ":" + num(seq);
            } else if (!is_sent && is_recv) {
                if (!phantom++) first_phantom = num(s) + ":" + num(seq);
            }
        }
    }
    if (lost) failure(num(lost) + " messages sent and never received (first: sender:seq " + first_lost + ")");
    if (phantom)
        failure(num(phantom) + " messages received whose send failed (first: sender:seq " + first_phantom + ")");
    if (dups) failure(num(dups) + " messages received twice");
    if (bad_w) failure(num(bad_w) + " malformed messages received");
    if (torn) failure(num(torn) + " torn reads of the seqlock block");
    report_["messages_sent"] = num(sent);
    report_["messages_received"] = num(received);
    report_["messages_drained_at_end"] = num(drained);
    report_["messages_from_dead_receivers"] = num(dead_taken);
    report_["messages_in_doubt"] = num(doubt) + " (" + num(doubt_arrived) + " arrived)";
    report_["messages_lost"] = num(lost);
    report_["messages_phantom"] = num(phantom);
    report_["messages_duplicated"] = num(dups);
    report_["pv_cycles"] = num(pv) + " (V called again after -EBUSY " + num(v_busy) + " times)";
    report_["pings"] = num(ping_ok) + " answered, " + num(ping_down) + " target down, " + num(ping_late) +
                       " target late (stopped)";
    report_["unexpected_statuses"] = num(errors);
}

// soak.sem: with every worker gone and the units of dead holders given
// back, count = initial - L, where L (units lost with a holder that died
// inside P or V) is at most the deaths counted in sem_doubt. The seqlock
// block: even sequence, every word equal, and the value between the
// confirmed writes and those plus the writes a death left in doubt.
void Driver::check_sem_and_shm() {
    const int value = chm_rsem_value(sem_), waiting = chm_rsem_waiting(sem_);
    const int64_t lost_units = int64_t(opt_.sem_units) - value;
    if (waiting != 0) failure("soak.sem has " + std::to_string(waiting) + " waiters after the end");
    if (value < 0 || lost_units < 0 || uint64_t(lost_units) > n_.sem_doubt)
        failure("soak.sem count " + std::to_string(value) + " after the end: " + num(opt_.sem_units) +
                " units, " + num(n_.sem_doubt) + " deaths inside P or V");
    report_["sem_count_end"] = std::to_string(value) + " of " + num(opt_.sem_units) + " (units lost " +
                               std::to_string(lost_units) + ", deaths inside P/V " + num(n_.sem_doubt) +
                               ", units given back for dead holders " + num(n_.units_returned) + ")";
    const int r = chm_spin_lock(&shm_->lock, 0, 2000000000ull);
    if (r != 0 && r != -EOWNERDEAD) {
        failure("soak.shm lock at the end: " + std::to_string(r));
        return;
    }
    bool repaired = false;
    if (shm_->seq & 1u) {  // the last writer died mid-write: finish it, as a worker would
        for (int i = 1; i < SOAK_SHM_WORDS; ++i) shm_->word[i] = shm_->word[0];
        ++shm_->seq;
        repaired = true;
    }
    uint64_t confirmed = 0, owner_dead = r == -EOWNERDEAD, repairs = repaired;
    for (unsigned i = 0; i < led_->workers; ++i) {
        confirmed += led_->w[i].shm_writes;
        owner_dead += led_->w[i].owner_dead;
        repairs += led_->w[i].repairs;
    }
    const uint64_t v = shm_->word[0];
    for (int i = 1; i < SOAK_SHM_WORDS; ++i)
        if (shm_->word[i] != v) failure("soak.shm words differ at the end: word " + std::to_string(i));
    if (v < confirmed || v > confirmed + n_.shm_doubt)
        failure("soak.shm holds " + num(v) + " writes; confirmed " + num(confirmed) + ", in doubt " +
                num(n_.shm_doubt));
    report_["shm_writes"] = num(v) + " (confirmed " + num(confirmed) + ", in doubt " + num(n_.shm_doubt) +
                            ", lock taken from a dead holder " + num(owner_dead) + ", half-made writes finished " +
                            num(repairs) + ")";
    if (chm_spin_unlock(&shm_->lock) != 0) failure("soak.shm unlock at the end");
}

// The state variables soak.v1..R with every worker gone: no writer claim
// left, one whole value, and that value (the writes of every incarnation
// of its writer: each goes on from the last) between the writes confirmed
// and those plus the writes a death left in doubt. Every incarnation of a
// writer claimed its variable at once, a dead predecessor's claim
// notwithstanding (a refusal is a worker error, reported above); no reader
// saw a torn value or one older than it had seen.
void Driver::check_svars() {
    uint64_t writes = 0, reads = 0, retry = 0, claims = 0, torn = 0, back = 0, doubt = 0;
    for (unsigned i = 0; i < led_->workers; ++i) {
        const soak_worker_t& w = led_->w[i];
        reads += w.svar_reads;
        retry += w.svar_retry;
        torn += w.svar_torn;
        back += w.svar_back;
    }
    if (torn) failure(num(torn) + " torn reads of a state variable");
    if (back) failure(num(back) + " reads of a state variable older than one the reader had seen");
    std::string values;
    for (unsigned k = 1; k <= opt_.rtpus; ++k) {
        const std::string name = "soak.v" + std::to_string(k);
        const soak_worker_t& w = led_->w[k - 1];
        writes += w.svar_writes;
        claims += w.svar_claims;
        doubt += n_.svar_doubt[k];
        double v[SOAK_SVAR_ELEMS] = {};
        chm_svar_info_t info{};
        const int r = chm_svar_get(name.c_str(), v, sizeof v), ri = chm_svar_info(name.c_str(), &info);
        if (r || ri) {
            failure(name + " at the end: status " + std::to_string(r ? r : ri) + " " + chm_bp_last_error());
            continue;
        }
        if (info.has_writer) failure(name + " still has a writer after every worker ended: " + info.writer);
        for (int e = 1; e < SOAK_SVAR_ELEMS; ++e)
            if (v[e] != v[0]) failure(name + " is torn at the end: element " + std::to_string(e));
        const uint64_t val = uint64_t(v[0]);
        if (val < w.svar_writes || val > w.svar_writes + n_.svar_doubt[k])
            failure(name + " holds " + num(val) + " writes; its writer confirmed " + num(w.svar_writes) +
                    ", in doubt " + num(n_.svar_doubt[k]));
        values += (values.empty() ? "" : ", ") + name + " " + num(val);
    }
    report_["svar"] = num(writes) + " writes (" + num(doubt) + " in doubt), " + num(reads) + " reads (" + num(retry) +
                      " kept the old copy: -EAGAIN), " + num(claims) + " writer claims by new incarnations, " +
                      num(torn) + " torn, " + num(back) + " backwards; at the end " + values;
}

// Leave the backplane, run chimera-bpcheck on the file at rest, remove the
// directory, and look for anything left: processes naming it, the directory.
void Driver::check_file_and_leftovers() {
    chm_bp_status_t st{};
    if (chm_bp_status(&st) == 0) {
        unsigned others = 0;
        for (std::uint32_t i = 0; i < st.slots; ++i)
            if (int(i) != st.self && st.slot[i].state != CHM_BP_FREE && st.slot[i].state != CHM_BP_DEAD) ++others;
        if (others) failure(num(others) + " slots still taken after every worker ended");
        report_["backplane_recoveries"] = num(st.recoveries);
    }
    for (chm_msgq_t* q : q_)
        if (chm_msgq_close(q) != 0) failure("closing a queue");
    if (chm_rsem_close(sem_) != 0) failure("closing soak.sem");
    if (chm_shm_detach(shm_) != 0) failure("detaching soak.shm");
    if (chm_bp_leave() != 0) failure(std::string("leaving the backplane: ") + chm_bp_last_error());
    const std::string out = dir_ + "/bpcheck.out";
    const std::string cmd = opt_.bpcheck_bin + " " + bp_ + " > " + out + " 2>&1";
    const int cst = std::system(cmd.c_str());
    std::string text;
    if (FILE* f = std::fopen(out.c_str(), "r")) {
        char line[512];
        while (std::fgets(line, sizeof line, f)) text += line;
        std::fclose(f);
    }
    const bool clean = WIFEXITED(cst) && WEXITSTATUS(cst) == 0;
    report_["checker"] = clean ? "clean" : "PROBLEMS";
    if (!clean) failure("chimera-bpcheck exit " + std::to_string(WEXITSTATUS(cst)) + ":\n" + text);
    for (const Proc& p : procs_)
        if (p.pid > 0) failure(p.name() + " still has a process");
    const std::vector<pid_t> left = leftover_processes();
    for (pid_t pid : left) {
        failure("process " + std::to_string(pid) + " still names " + dir_);
        kill(pid, SIGKILL);
    }
    chm::test::remove_private_dir(dir_);
    struct stat sb;
    const bool gone = ::stat(dir_.c_str(), &sb) != 0;
    if (!gone) failure(dir_ + " could not be removed");
    report_["left_behind"] = left.empty() && gone ? "nothing" : "SOMETHING";
}

}  // namespace soak
