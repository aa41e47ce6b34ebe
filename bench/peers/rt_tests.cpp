// Peers from Debian's rt-tests, run as they are and parsed from their
// summary lines: cyclictest (timer wake-up latency at 1 kHz) beside the
// sigwaitinfo loop, and ptsematest, svsematest, pmqtest and sigwaittest
// (wake-up latency of one thread or process by another) beside the suite's
// own ping-pongs. Each reports min / avg / max in whole microseconds; the row
// gives the average as its value (the tools report no median).
//
// They ask for SCHED_FIFO priority 80 (-p 80); where that is refused they are
// run again without it, and the row's config says which one it got.
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <regex>
#include <string>
#include <vector>

#include "../harness.hpp"

extern char** environ;

namespace chm::bench {
namespace {

bool on_path(const std::string& exe) {
    const char* path = std::getenv("PATH");
    std::string p = path ? path : "/usr/bin:/bin";
    for (std::size_t a = 0; a <= p.size();) {
        std::size_t b = p.find(':', a);
        if (b == std::string::npos) b = p.size();
        const std::string full = p.substr(a, b - a) + "/" + exe;
        if (access(full.c_str(), X_OK) == 0) return true;
        a = b + 1;
    }
    return false;
}

// Run argv with stdout and stderr captured; on timeout SIGINT (the tools
// print their summary on it), then SIGKILL. Always reaped.
std::string run_capture(const std::vector<std::string>& args, double timeout_s, int* status) {
    int fds[2];
    check(pipe2(fds, O_CLOEXEC) == 0, "pipe2");
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_adddup2(&fa, fds[1], 1);
    posix_spawn_file_actions_adddup2(&fa, fds[1], 2);
    std::vector<char*> argv;
    for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    pid_t pid;
    const int e = posix_spawnp(&pid, argv[0], &fa, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&fa);
    close(fds[1]);
    if (e != 0) {
        close(fds[0]);
        fail_errno("posix_spawnp " + args[0], e);
    }
    std::string out;
    const std::uint64_t deadline = mono_ns() + std::uint64_t(timeout_s * 1e9);
    int signals_sent = 0;
    for (;;) {
        if (mono_ns() > deadline + std::uint64_t(signals_sent) * 1000000000u || watchdog_fired()) {
            if (signals_sent >= 2) break;
            kill(pid, signals_sent++ == 0 ? SIGINT : SIGKILL);
        }
        pollfd p{fds[0], POLLIN, 0};
        const int r = poll(&p, 1, 100);
        if (r < 0 && errno != EINTR) break;
        if (r <= 0) continue;
        char buf[4096];
        const ssize_t n = read(fds[0], buf, sizeof buf);
        if (n > 0) out.append(buf, std::size_t(n));
        else if (n == 0 || errno != EINTR) break;  // EOF: the tool exited
    }
    close(fds[0]);
    if (signals_sent >= 2) kill(pid, SIGKILL);
    while (waitpid(pid, status, 0) < 0 && errno == EINTR) {
    }
    if (signals_sent) *status = -1;
    return out;
}

struct Summary {
    bool ok = false;
    double min_us = 0, avg_us = 0, max_us = 0;
};

// "#1 -> #0, Min    1, Cur   66, Avg   74, Max  438" (the *sematest family)
// "T: 0 ( 6278) P:80 I:1000 C:   1000 Min:     33 Act:  103 Avg:  110 Max:    1144"
Summary parse(const std::string& out) {
    static const std::regex line(R"(Min:?\s+(\d+),?\s+(?:Cur|Act):?\s+\d+,?\s+Avg:?\s+(\d+),?\s+Max:?\s+(\d+))");
    std::smatch m;
    Summary s;
    if (std::regex_search(out, m, line)) {
        s.ok = true;
        s.min_us = std::stod(m[1]);
        s.avg_us = std::stod(m[2]);
        s.max_us = std::stod(m[3]);
    }
    return s;
}

struct ToolRun {
    const char* row;
    const char* exe;
    std::vector<std::string> args;  // without -p and without -a
    int affinity;                   // a CPU for all threads, or -1: thread N on CPU N
    double seconds;                 // the run's expected length
};

void rt_tests(Session& s) {
    const bool q = s.quick();
    // cyclictest as many periods as the sigwaitinfo loop beside it.
    const std::string loops = q ? "200" : "2000", cyc_loops = q ? "500" : "10000";
    const int a = s.cpu(0);
    const bool cpus01 = s.options().cpus.size() >= 2 &&
                        std::count(s.options().cpus.begin(), s.options().cpus.end(), 0) &&
                        std::count(s.options().cpus.begin(), s.options().cpus.end(), 1);
    const double t = q ? 0.1 : 1.0;
    const std::vector<ToolRun> runs = {
        {"peer_rt_cyclictest_1khz", "cyclictest", {"-q", "-t", "1", "-i", "1000", "-l", cyc_loops},
         a, q ? 0.5 : 10.0},
        {"peer_rt_ptsematest_same_core", "ptsematest", {"-q", "-i", "500", "-l", loops}, a, t},
        {"peer_rt_ptsematest_xcore", "ptsematest", {"-q", "-i", "500", "-l", loops}, -1, t},
        {"peer_rt_svsematest_same_core", "svsematest", {"-q", "-f", "-i", "500", "-l", loops}, a, t},
        {"peer_rt_svsematest_xcore", "svsematest", {"-q", "-f", "-i", "500", "-l", loops}, -1, t},
        {"peer_rt_pmqtest_same_core", "pmqtest", {"-q", "-i", "500", "-l", loops}, a, t},
        {"peer_rt_pmqtest_xcore", "pmqtest", {"-q", "-i", "500", "-l", loops}, -1, t},
        {"peer_rt_sigwaittest_same_core", "sigwaittest", {"-q", "-f", "-i", "500", "-l", loops}, a, t},
        {"peer_rt_sigwaittest_xcore", "sigwaittest", {"-q", "-f", "-i", "500", "-l", loops}, -1, t},
    };
    bool fifo_ok = true;  // until a tool is refused SCHED_FIFO once
    std::string fifo_refusal;
    for (const ToolRun& r : runs) {
        if (!on_path(r.exe)) {
            s.skip(r.row, std::string(r.exe) + " not installed (Debian package rt-tests)");
            continue;
        }
        if (r.affinity < 0 && !cpus01) {
            s.skip(r.row, "the tools put thread N on CPU N; CPUs 0 and 1 are not both available");
            continue;
        }
        std::vector<std::string> args{r.exe};
        args.insert(args.end(), r.args.begin(), r.args.end());
        if (r.affinity >= 0) args.push_back("-a" + std::to_string(r.affinity));
        else args.push_back("-a");
        Summary sum;
        std::string used, out;
        int status = 0;
        if (fifo_ok) {
            std::vector<std::string> rt = args;
            rt.push_back("-p80");
            out = run_capture(rt, r.seconds * 3 + 10, &status);
            sum = parse(out);
            if (sum.ok && status == 0) {
                used = rt[0];
                for (std::size_t i = 1; i < rt.size(); ++i) used += " " + rt[i];
                used += " (SCHED_FIFO 80)";
            } else {
                fifo_ok = false;
                fifo_refusal = out.substr(0, out.find('\n'));
            }
        }
        if (!fifo_ok) {
            out = run_capture(args, r.seconds * 3 + 10, &status);
            sum = parse(out);
            used = args[0];
            for (std::size_t i = 1; i < args.size(); ++i) used += " " + args[i];
            used += " (SCHED_OTHER: -p 80 failed" + (fifo_refusal.empty() ? "" : ": " + fifo_refusal) + ")";
        }
        if (watchdog_fired()) throw std::runtime_error(std::string(r.exe) + ": timed out (watchdog)");
        if (!sum.ok || status != 0) {
            s.skip(r.row, std::string(r.exe) + " gave no summary line (exit status " +
                              std::to_string(status) + "): " + out.substr(0, 200));
            continue;
        }
        s.emit(r.row, used + "; average of its wake-ups, whole us", sum.avg_us * 1e3,
               sum.min_us * 1e3, sum.max_us * 1e3);
    }
}
CHM_BENCH_MEASUREMENT(rt_tests, "peer_rt_cyclictest_1khz", "peer_rt_ptsematest_same_core",
                      "peer_rt_ptsematest_xcore", "peer_rt_svsematest_same_core",
                      "peer_rt_svsematest_xcore", "peer_rt_pmqtest_same_core", "peer_rt_pmqtest_xcore",
                      "peer_rt_sigwaittest_same_core", "peer_rt_sigwaittest_xcore");

}  // namespace
}  // namespace chm::bench
