// The soak's worker processes: start an incarnation, reap it (bounded),
// and read back from the ledger what a dead one had in flight.
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <fstream>
#include <sstream>

#include <dirent.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include "soak.hpp"

namespace soak {

uint64_t now_ns() {
    timespec ts{};
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return uint64_t(ts.tv_sec) * 1000000000u + uint64_t(ts.tv_nsec);
}

void nap_ms(unsigned ms) {
    timespec ts{time_t(ms / 1000), long(ms % 1000) * 1000000L};
    while (nanosleep(&ts, &ts) != 0 && errno == EINTR) {
    }
}

std::string Proc::name() const {
    std::string w;
    for (unsigned i : ids) w += (w.empty() ? "" : ", ") + std::to_string(i);
    return rtpu ? "RTPU " + std::to_string(rtpu) + " (workers " + w + ")" : "host worker " + w;
}

// Fork and exec the next incarnation of `p`; output appended to its log.
void Driver::start(Proc& p) {
    // Every worker of the process takes the same next incarnation.
    const uint32_t inc = led_->w[p.id].inc + 1;
    for (unsigned i : p.ids) __atomic_store_n(&led_->w[i].inc, inc, __ATOMIC_SEQ_CST);
    const std::string id = std::to_string(p.id), incs = std::to_string(inc), seed = std::to_string(opt_.seed);
    std::vector<std::string> args;
    if (p.rtpu) {
        args = {opt_.rtpu_bin, "--backplane", bp_, "--rtpu", std::to_string(p.rtpu), "--name",
                "soak" + std::to_string(p.rtpu), "--stdio-log", opt_.worker_so, ledger_path_, incs, seed};
        for (unsigned i : p.ids) args.push_back(std::to_string(i));
    } else
        args = {opt_.host_bin, bp_, ledger_path_, id, incs, seed};
    const std::string log = dir_ + "/worker" + id + ".log";
    std::fflush(nullptr);
    const pid_t parent = getpid();
    const pid_t pid = fork();
    if (pid == 0) {
        prctl(PR_SET_PDEATHSIG, SIGKILL);  // a driver killed outright takes its workers with it
        if (getppid() != parent) _exit(127);  // it died before the line above
        setsid();  // its own session: a hangup of the driver's terminal or job is not its stop
        const int fd = open(log.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0600);
        if (fd >= 0) {
            dup2(fd, 1);
            dup2(fd, 2);
        }
        const int nul = open("/dev/null", O_RDONLY);
        if (nul >= 0) dup2(nul, 0);
        std::vector<char*> argv;
        for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
        argv.push_back(nullptr);
        execv(argv[0], argv.data());
        _exit(127);
    }
    if (pid < 0) {
        failure("fork for " + p.name() + ": " + std::strerror(errno));
        return;
    }
    p.pid = pid;
    p.state = Proc::Starting;
    p.since = p.floor = now_ns();
    p.killed = false;
}

// Wait up to timeout_ms for `p` to end; its wait status in *status.
bool Driver::reap(Proc& p, int timeout_ms, int* status) {
    const uint64_t end = now_ns() + uint64_t(timeout_ms) * 1000000u;
    for (;;) {
        const pid_t r = waitpid(p.pid, status, WNOHANG);
        if (r == p.pid) {
            p.pid = -1;
            return true;
        }
        if (r < 0 || now_ns() >= end) return false;
        nap_witness(1);  // a death slowed by the host's load is the host's stall
    }
}

// `p` is gone (reaped): take over what its incarnation left in flight.
// Only here, with the process certainly dead, are its ledger states final.
void Driver::absorb_death(Proc& p) {
    for (unsigned i : p.ids) absorb_worker(p, i);
}

void Driver::absorb_worker(const Proc& p, unsigned id) {
    soak_worker_t& w = led_->w[id];
    if (w.send_state == SOAK_SEND_PENDING) doubt_[id].insert(w.last_seq);  // sent or not: both are right
    w.send_state = SOAK_SEND_IDLE;
    if (w.rbuf.magic == SOAK_MSG_MAGIC) {
        // A receive copied this message and the worker died before it
        // marked it (or before it cleared the buffer). It counts as
        // received only if no one else gets it (finish.cpp): a receive cut
        // short before it committed leaves the message queued.
        if (soak_msg_ok(&w.rbuf, int(w.rbuf.len), led_->workers)) dead_bufs_.push_back(w.rbuf);
        else ++n_.dead_bufs_partial;
    }
    w.rbuf.magic = 0;
    w.recv_state = 0;
    if (w.sem_state == SOAK_SEM_HELD) {
        // It held a unit of soak.sem: give it back for it, as an owner-died
        // recovery would (a remote semaphore does not know its holders).
        const int r = chm_rsem_v(sem_);
        if (r) failure("V for dead " + p.name() + ": " + std::to_string(r));
        ++n_.units_returned;
    } else if (w.sem_state != SOAK_SEM_IDLE) {
        ++n_.sem_doubt;  // died inside P or V: the unit may be lost with it
    }
    w.sem_state = SOAK_SEM_IDLE;
    if (w.shm_state == SOAK_SHM_WRITING) ++n_.shm_doubt;  // that write may or may not count
    w.shm_state = SOAK_SHM_IDLE;
    if (w.svar_writing && id < opt_.rtpus) ++n_.svar_doubt[id + 1];  // that value may or may not be out
    w.svar_writing = 0;
    w.op = SOAK_OP_IDLE;
}

// Processes still alive whose command line names the soak's directory.
std::vector<pid_t> Driver::leftover_processes() const {
    std::vector<pid_t> out;
    DIR* d = opendir("/proc");
    if (!d) return out;
    while (dirent* e = readdir(d)) {
        char* end = nullptr;
        const long pid = std::strtol(e->d_name, &end, 10);
        if (!end || *end || pid <= 0 || pid == getpid()) continue;
        std::ifstream f(std::string("/proc/") + e->d_name + "/cmdline");
        std::stringstream s;
        s << f.rdbuf();
        if (s.str().find(dir_) != std::string::npos) out.push_back(pid_t(pid));
    }
    closedir(d);
    return out;
}

}  // namespace soak
