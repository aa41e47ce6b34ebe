// chimera-soak: the chaos soak (`make soak`, suite `soak`; docs/backplane.md,
// "Chaos soak"). On a private backplane file, RTPUs and host processes
// exchange messages, semaphore units, a seqlock-protected block and state
// variables, and a servo controller switches modules on the RTPUs, while
// this driver kills, stops/continues, terminates and restarts them at
// random; then it stops everything in order and checks the accounting,
// the checker's verdict on the file and that nothing is left behind.
// Exit 0 when every check held, 1 otherwise, 2 for bad arguments.
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include <fcntl.h>
#include <signal.h>
#include <sys/mman.h>
#include <unistd.h>

#include "../private_dir.hpp"
#include "chimera/bp.h"
#include "chimera/shm.h"
#include "chimera/spin.h"
#include "chimera/svar.h"
#include "soak.hpp"

namespace soak {

volatile int g_interrupted = 0;

void Driver::failure(const std::string& what) {
    failures_.push_back(what);
    std::fprintf(stderr, "soak: FAILED: %s\n", what.c_str());
}

uint64_t Driver::rnd() {  // xorshift64*: the whole run follows from the seed
    rng_ ^= rng_ >> 12;
    rng_ ^= rng_ << 25;
    rng_ ^= rng_ >> 27;
    return rng_ * 2685821657736338717ull;
}

namespace {

bool make_ledger(const std::string& path, unsigned workers, unsigned rtpus, unsigned units, soak_ledger_t** out) {
    const int fd = open(path.c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
    if (fd < 0 || ftruncate(fd, off_t(SOAK_LEDGER_SIZE)) != 0) return false;
    void* m = mmap(nullptr, SOAK_LEDGER_SIZE, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
    close(fd);
    if (m == MAP_FAILED) return false;
    auto* l = static_cast<soak_ledger_t*>(m);
    l->magic = SOAK_MSG_MAGIC;
    l->workers = workers;
    l->sem_units = units;
    l->rtpus = rtpus;
    l->layout = sizeof(soak_ledger_t);
    *out = l;
    return true;
}

}  // namespace

int Driver::run() {
    if (!opt_.seed) opt_.seed = (now_ns() ^ uint64_t(getpid()) << 32) % 1000000007u + 1;
    rng_ = opt_.seed * 0x9E3779B97F4A7C15ull | 1u;
    const unsigned workers = 2 * opt_.rtpus + opt_.hosts;  // two tasks per RTPU
    bound_ns_ = (uint64_t(opt_.stop_max_ms) + SOAK_OP_TIMEOUT_NS / 1000000u + opt_.slack_ms) * 1000000u;
    std::printf("soak: seed %llu, %u s, %u RTPUs (two worker tasks each) + %u host processes, stall bound %llu ms "
                "(longest stop %u + operation bound %llu + slack %u)\n",
                (unsigned long long)opt_.seed, opt_.seconds, opt_.rtpus, opt_.hosts,
                (unsigned long long)(bound_ns_ / 1000000u), opt_.stop_max_ms,
                (unsigned long long)(SOAK_OP_TIMEOUT_NS / 1000000u), opt_.slack_ms);
    std::fflush(stdout);
    dir_ = chm::test::make_private_dir("chm-soak-");
    if (dir_.empty()) return std::fprintf(stderr, "soak: mkdtemp: %s\n", std::strerror(errno)), 1;
    bp_ = dir_ + "/soak.bp";
    ledger_path_ = dir_ + "/ledger";
    chm_bp_config_t c;
    chm_bp_config_init(&c);
    c.rtpu_slots = 12;
    c.ring_records = 16;
    c.local_window_size = 64 * 1024;
    c.common_size = 1024 * 1024;  // the state-variable table takes half of it
    c.registry_capacity = 32;
    if (chm_bp_create(bp_.c_str(), &c) != 0 || chm_bp_attach_host(bp_.c_str(), "soak-driver", nullptr) != 0 ||
        !make_ledger(ledger_path_, workers, opt_.rtpus, opt_.sem_units, &led_)) {
        std::fprintf(stderr, "soak: setting up %s: %s %s\n", dir_.c_str(), chm_bp_last_error(), std::strerror(errno));
        (void)!chm_bp_leave();  // a failed setup: nothing to check
        chm::test::remove_private_dir(dir_);
        return 1;
    }
    chm_msgq_attr_t a;
    chm_msgq_attr_init(&a);
    a.max_msg = SOAK_MSG_MAX;
    a.max_count = 16;  // small: senders fill it and wait too
    a.max_waiters = 8;
    int r = 0;
    for (int i = 0; i < SOAK_QUEUES && !r; ++i)
        r = chm_msgq_create(("soak.q" + std::to_string(i)).c_str(), &a, CHM_MSGQ_COMMON, &q_[i]);
    void* shm = nullptr;
    if (!r) r = chm_rsem_create("soak.sem", CHM_SEM_COUNTING, opt_.sem_units, CHM_SHM_COMMON, &sem_);
    if (!r) r = chm_shm_create("soak.shm", sizeof(soak_shm_t), CHM_SHM_COMMON, &shm);
    shm_ = static_cast<soak_shm_t*>(shm);
    if (!r) r = chm_spin_init(&shm_->lock);
    for (unsigned k = 1; k <= opt_.rtpus && !r; ++k) {
        const std::string name = "soak.v" + std::to_string(k);
        chm_svar_decl_t d{name.c_str(), CHM_SVAR_DOUBLE, SOAK_SVAR_ELEMS, 1, "writes"};
        r = chm_svar_declare(&d);
    }
    if (!r) r = servo_objects();
    if (r) {
        std::fprintf(stderr, "soak: creating the objects: %d %s\n", r, chm_bp_last_error());
        (void)!chm_bp_leave();  // a failed setup: nothing to check
        chm::test::remove_private_dir(dir_);
        return 1;
    }
    doubt_.resize(workers);
    worst_per_worker_.assign(workers, 0);
    stall_reported_.assign(workers, 0);
    seen_from_.assign(workers, 0);
    host_at_.assign(workers, 0);
    // Workers 0..R-1: RTPUs' first tasks; R..R+H-1: hosts; then the RTPUs'
    // second tasks.
    for (unsigned i = 0; i < opt_.rtpus + opt_.hosts; ++i) {
        Proc p;
        p.id = i;
        p.ids = {i};
        if (i < opt_.rtpus) {
            p.rtpu = int(i) + 1;
            p.ids.push_back(opt_.rtpus + opt_.hosts + i);
        }
        procs_.push_back(p);
    }
    t0_ = now_ns();
    for (Proc& p : procs_) start(p);
    start_servo();
    chaos_phase();
    if (g_interrupted) {
        abandon();
        return 1;
    }
    finish();

    uint64_t ops = 0;
    for (unsigned i = 0; i < workers; ++i)
        for (uint64_t k : led_->w[i].op_count) ops += k;
    std::string per;
    for (unsigned i = 0; i < workers; ++i)
        per += (i ? ", " : "") + std::to_string(worst_per_worker_[i] / 1000000u);
    std::printf("soak: summary (seed %llu, %u s)\n", (unsigned long long)opt_.seed, opt_.seconds);
    std::printf("  kills %llu (RTPUs %llu, hosts %llu; of them while stopped %llu, while starting %llu), "
                "SIGTERM stops %llu (of hosts %llu), SIGSTOP/SIGCONT %llu (while starting %llu), restarts %llu\n",
                (unsigned long long)n_.kills, (unsigned long long)n_.kills_rtpu, (unsigned long long)n_.kills_host,
                (unsigned long long)n_.kills_stopped, (unsigned long long)n_.kills_starting,
                (unsigned long long)n_.terms, (unsigned long long)n_.terms_host, (unsigned long long)n_.stops, (unsigned long long)n_.stops_starting,
                (unsigned long long)n_.restarts);
    std::printf("  operations %llu\n", (unsigned long long)ops);
    for (const auto& [k, v] : report_) std::printf("  %s: %s\n", k.c_str(), v.c_str());
    std::printf("  worst survivor stall %.1f ms (worker %u, operation %s%s%s; bound %llu ms); per worker [%s] ms; "
                "%llu samples; driver's longest tick %.1f ms\n"
                "  worst stall beyond the host's own stalls %.1f ms; the host stalled the driver %.1f ms in all\n",
                worst_.ns / 1e6, worst_.worker, op_name(worst_.op), worst_.peer_stopped.empty() ? "" : ", while ",
                worst_.peer_stopped.empty() ? "" : (worst_.peer_stopped + " was stopped").c_str(),
                (unsigned long long)(bound_ns_ / 1000000u), per.c_str(), (unsigned long long)n_.stall_samples,
                worst_tick_gap_ / 1e6, worst_net_ / 1e6, host_stall_ / 1e6);
    std::printf("  longest time an object served nobody: %.1f ms (%s; bound %llu ms)\n", worst_obj_ns_ / 1e6,
                object_name(worst_obj_), (unsigned long long)(bound_ns_ / 1000000u));
    std::printf("soak: %s (%zu failed checks)\n", failures_.empty() ? "PASSED" : "FAILED", failures_.size());
    return failures_.empty() ? 0 : 1;
}

}  // namespace soak

namespace {

[[noreturn]] void usage(const char* why) {
    std::fprintf(stderr,
                 "chimera-soak: %s\n"
                 "usage: chimera-soak [--seconds N] [--seed N] [--rtpus N] [--hosts N] [--quiet] [--no-servo-chaos]\n"
                 "                    [--servo-fault 0|1|2] (every controller restarted in the chaos kills itself\n"
                 "                    at servo.switch.prepared, committed_one or decided)\n"
                 "                    [--rtpu-bin PATH] [--host-bin PATH] [--worker PATH] [--bpcheck PATH]\n"
                 "                    [--servo-bin PATH]\n",
                 why);
    std::exit(2);
}

unsigned long long number(const char* opt, const char* v, unsigned long long lo, unsigned long long hi) {
    char* end = nullptr;
    errno = 0;
    const unsigned long long n = v ? std::strtoull(v, &end, 10) : 0;
    if (!v || !*v || *end || errno || n < lo || n > hi) {
        std::fprintf(stderr, "chimera-soak: %s \"%s\": not a number in %llu..%llu\n", opt, v ? v : "", lo, hi);
        std::exit(2);
    }
    return n;
}

}  // namespace

int main(int argc, char** argv) {
    soak::Options o;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        const char* v = i + 1 < argc ? argv[i + 1] : nullptr;
        if (a == "--no-servo-chaos") {
            o.servo_chaos = false;
            continue;
        }
        if (a == "--quiet") {
            o.quiet = true;
            continue;
        }
        if (!v) usage(("option " + a + " needs a value").c_str());
        ++i;
        if (a == "--seconds") o.seconds = unsigned(number("--seconds", v, 1, 86400));
        else if (a == "--seed") o.seed = number("--seed", v, 0, ~0ull >> 1);
        else if (a == "--servo-fault") o.servo_fault = int(number("--servo-fault", v, 0, 2));
        else if (a == "--rtpus") o.rtpus = unsigned(number("--rtpus", v, 1, 4));
        else if (a == "--hosts") o.hosts = unsigned(number("--hosts", v, 0, 2));
        else if (a == "--rtpu-bin") o.rtpu_bin = v;
        else if (a == "--host-bin") o.host_bin = v;
        else if (a == "--worker") o.worker_so = v;
        else if (a == "--bpcheck") o.bpcheck_bin = v;
        else if (a == "--servo-bin") o.servo_bin = v;
        else usage(("unknown option " + a).c_str());
    }
    if (2 * o.rtpus + o.hosts > SOAK_MAX_WORKERS) usage("more than 8 workers (two per RTPU, one per host)");
    if (o.rtpu_bin.empty() || o.host_bin.empty() || o.worker_so.empty() || o.bpcheck_bin.empty())
        usage("--rtpu-bin, --host-bin, --worker and --bpcheck are required");
    signal(SIGPIPE, SIG_IGN);
    struct sigaction sa{};
    sa.sa_handler = [](int) { soak::g_interrupted = 1; };
    sigemptyset(&sa.sa_mask);
    for (int sig : {SIGINT, SIGTERM, SIGHUP}) {
        struct sigaction old{};
        sigaction(sig, nullptr, &old);
        if (old.sa_handler != SIG_IGN) sigaction(sig, &sa, nullptr);  // nohup's ignored SIGHUP stays ignored
    }
    return soak::Driver(o).run();
}
