// Backplane rows with real RTPUs: the shared plumbing (see rtpu.hpp).
#include "rtpu.hpp"

#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <exception>
#include <stdexcept>

#include "../../tests/private_dir.hpp"
#include "../kernel/kbench.hpp"
#include "ipc/wake/wake.hpp"

namespace chm::bench::ipcb {

namespace {

int g_work = 0;                  // spawned tasks that have not returned yet
std::uint64_t g_deadline_ns = 0; // child: stop after this (0: never)
int g_parent = 0;                // child: stop when this process is gone

constexpr int kGuardPriority = 1000;
constexpr std::uint64_t kGuardPeriodNs = 20'000'000;

void guard_task(void*) {
    for (;;) {
        chm_task_pause_until(chm_time_now() + kGuardPeriodNs);
        if (g_parent) {
            if (getppid() != g_parent || (g_deadline_ns && mono_ns() > g_deadline_ns)) chm_kernel_stop(0);
        } else if (const char* why = abort_reason()) {
            kb::Kernel::store_failure(std::make_exception_ptr(std::runtime_error(why)));
            kb::Kernel::stop_failed();
        }
    }
}

void run_work(void* p) {
    kb::guarded([p] { (*static_cast<std::function<void()>*>(p))(); });
    if (--g_work == 0) chm_kernel_stop(0);
}

kb::TaskSpec spec(int priority, const char* name) {
    kb::TaskSpec t;
    t.priority = priority;
    t.name = name;
    return t;
}

}  // namespace

[[noreturn]] void fail_bp(const std::string& what, int r) {
    throw std::runtime_error(what + ": " + chm_bp_last_error() + " (" + std::strerror(r < 0 ? -r : r) + ")");
}

Stats measure_part(Session& s, double fraction, const std::function<double(std::uint64_t)>& body,
                   std::string* how) {
    Options o = s.options();
    o.run_ns *= fraction;
    std::vector<Measured> unused;
    Session part(o, &unused);
    const Stats st = part.measure(body);
    if (how)
        *how = "median of " + std::to_string(st.runs) + " runs x " + std::to_string(st.iters_per_run) + " ops";
    return st;
}

double child_limit(const Session& s) { return s.options().watchdog_s + 10; }

BackplaneFile::BackplaneFile(const char* what, std::uint32_t slots, std::uint32_t window) {
    // The tests' private directory (tests/private_dir.hpp): whatever the
    // backplane leaves beside its file goes with it.
    dir = chm::test::make_private_dir((std::string("chimera-bench-") + what + "-").c_str());
    if (dir.empty()) throw std::runtime_error(std::string("mkdtemp in /dev/shm: ") + std::strerror(errno));
    path = dir + "/" + what + ".bp";
    chm_bp_config_t c;
    chm_bp_config_init(&c);
    c.rtpu_slots = slots;
    c.local_window_size = window;
    if (const int r = chm_bp_create(path.c_str(), &c)) fail_bp("chm_bp_create", r);
}

BackplaneFile::~BackplaneFile() { chm::test::remove_private_dir(dir); }

Joined::Joined(const std::string& path, int slot) {
    if (const int r = chm_bp_join(path.c_str(), slot, "bench")) fail_bp("chm_bp_join", r);
}

Joined::~Joined() { (void)chm_bp_leave(); }

Kernel::Kernel(int slot, std::uint64_t idle_poll_ns, std::uint64_t deadline_ns, int parent) {
    chm_kernel_config_t cfg;
    chm_kernel_config_init(&cfg);
    cfg.rtpu_id = slot;  // otherwise chm_kernel_config_init's: MUF, 1 ms quantum, accounting
    cfg.idle_poll_ns = idle_poll_ns;
    kb::Kernel::forget_failure();
    g_work = 0;
    g_deadline_ns = deadline_ns;
    g_parent = parent;
    if (const int e = chm_kernel_init(&cfg))
        throw std::runtime_error("chm_kernel_init: error " + std::to_string(e));
    if (const int e = chm::ipc::wake_bind_kernel()) {
        chm_kernel_fini();
        throw std::runtime_error("wake_bind_kernel: error " + std::to_string(e));
    }
    bound_ = true;
    try {
        kb::spawn(guard_task, nullptr, spec(kGuardPriority, "guard"));
    } catch (...) {
        chm::ipc::wake_unbind_kernel();
        chm_kernel_fini();
        throw;
    }
}

Kernel::~Kernel() {
    if (bound_) chm::ipc::wake_unbind_kernel();
    chm_kernel_fini();
}

void Kernel::spawn(std::function<void()>* fn, int priority, const char* name) {
    kb::spawn(run_work, fn, spec(priority, name));
    ++g_work;
}

void Kernel::spawn_endless(std::function<void()>* fn, int priority, const char* name) {
    kb::spawn_fn(fn, spec(priority, name));  // guarded, not counted
}

void Kernel::run() { kb::Kernel::run_and_rethrow(); }

std::unique_ptr<Child> rtpu_child(int cpu, const std::string& path, int slot,
                                  std::uint64_t idle_poll_ns, double limit_s,
                                  const std::function<void(Kernel&)>& tasks) {
    const int parent = int(getpid());
    return std::make_unique<Child>(cpu, [=, &tasks] {
        // A forked child does not inherit the attachment: join anew.
        if (chm_bp_join(path.c_str(), slot, "partner") != 0) {
            std::fprintf(stderr, "chimera-bench RTPU %d: join: %s\n", slot, chm_bp_last_error());
            return 2;
        }
        int rc = 0;
        try {
            Kernel k(slot, idle_poll_ns, mono_ns() + std::uint64_t(limit_s * 1e9), parent);
            tasks(k);
            k.run();
        } catch (const std::exception& e) {
            std::fprintf(stderr, "chimera-bench RTPU %d: %s\n", slot, e.what());
            rc = 3;
        }
        (void)chm_bp_leave();
        return rc;
    });
}

void wait_rtpus_running(const std::vector<int>& slots) {
    for (;;) {
        chm_bp_status_t st;
        if (const int r = chm_bp_status(&st)) fail_bp("chm_bp_status", r);
        bool all = true;
        for (int s : slots)
            all = all && st.slot[s].state == CHM_BP_RUNNING && st.slot[s].tid > 0;
        if (all) return;
        if (const char* why = abort_reason()) throw std::runtime_error(std::string(why) + " (partner RTPUs starting)");
        usleep(1000);
    }
}

}  // namespace chm::bench::ipcb
