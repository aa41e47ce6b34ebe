// chimera start: create the backplane if absent, refuse a system that is
// already running, and start RTPUs 1..N as detached chimera-rtpu processes
// (own session, stdin /dev/null, output appended to PATH.rtpuN.log unless
// --log-terminal), then wait (bounded) until each is RUNNING in the table
// and answers express mail. If any fails, the ones it started are stopped
// and a backplane it created is removed.
#include <cerrno>
#include <climits>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <string>
#include <vector>

#include <fcntl.h>
#include <sched.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "chimera/bp.h"
#include "chimera/rtpu.h"
#include "cmd.hpp"

namespace chimera_cmd {

namespace {

// chimera-rtpu beside this executable (installed), in the build tree's
// tools/chimera-rtpu, or on PATH; $CHIMERA_RTPU_BIN first.
std::string find_rtpu_binary() {
    if (const char* e = std::getenv("CHIMERA_RTPU_BIN")) return e;
    char self[PATH_MAX];
    const ssize_t n = readlink("/proc/self/exe", self, sizeof self - 1);
    if (n > 0) {
        self[n] = 0;
        std::string dir(self);
        dir = dir.substr(0, dir.rfind('/'));
        for (const std::string& c : {dir + "/chimera-rtpu", dir + "/../chimera-rtpu/chimera-rtpu"})
            if (access(c.c_str(), X_OK) == 0) return c;
    }
    return "chimera-rtpu";  // execvp searches PATH
}

// The last non-empty line of a file (an RTPU's log), for error messages.
std::string last_line(const std::string& path) {
    FILE* f = std::fopen(path.c_str(), "r");
    if (!f) return "";
    char buf[512];
    std::string last;
    while (std::fgets(buf, sizeof buf, f)) {
        std::string l(buf);
        while (!l.empty() && (l.back() == '\n' || l.back() == '\r')) l.pop_back();
        if (!l.empty()) last = l;
    }
    std::fclose(f);
    return last;
}

// The n-th CPU (0-based, round robin) this process may run on.
int nth_allowed_cpu(int n) {
    cpu_set_t allowed;
    CPU_ZERO(&allowed);
    if (sched_getaffinity(0, sizeof allowed, &allowed) != 0 || CPU_COUNT(&allowed) == 0) return n;
    n %= CPU_COUNT(&allowed);
    for (int c = 0; c < CPU_SETSIZE; ++c)
        if (CPU_ISSET(c, &allowed) && n-- == 0) return c;
    return 0;
}

// An RTPU's log, opened here so that a refusal stops the start before any
// RTPU runs: never through a link, appended (never truncated under an RTPU
// still writing it), mode 0640, and a regular file of ours with one link
// (not someone's file linked into the directory).
int open_log(const std::string& log) {
    const int fd = open(log.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_NOFOLLOW | O_NONBLOCK | O_CLOEXEC, 0640);
    if (fd < 0) {
        say("cannot open the log %s: %s%s", log.c_str(), std::strerror(errno),
            errno == ELOOP ? " (a symbolic link: remove it after checking who made it)" : "");
        return -1;
    }
    struct stat st{};
    if (fstat(fd, &st) != 0 || !S_ISREG(st.st_mode) || st.st_uid != geteuid() || st.st_nlink != 1 ||
        (st.st_mode & 0022)) {
        say("log %s: owner uid %u, mode 0%o, %u links: refused, a log must be a regular file of yours with one "
            "link that others cannot write; fix: remove it after checking who made it",
            log.c_str(), unsigned(st.st_uid), unsigned(st.st_mode & 07777), unsigned(st.st_nlink));
        close(fd);
        return -1;
    }
    return fd;
}

pid_t launch(const Options& o, const StartPlan& p, int n, const std::string& bin, int log_fd) {
    std::vector<std::string> args = {bin, "--backplane", o.backplane, "--rtpu", std::to_string(n)};
    if (n == 0) {
        args.insert(args.end(), {"--host-server", p.host_root});
        if (p.allow_shell) args.push_back("--host-allow-shell");
    }
    // The host server does the host's blocking work: no real-time
    // priority, pinning or programs of its own.
    if (!p.policy.empty() && n > 0) args.insert(args.end(), {"--policy", p.policy});
    if (n > 0) args.insert(args.end(), p.rtpu_options.begin(), p.rtpu_options.end());
    if (p.pin && n > 0) args.insert(args.end(), {"--cpu", std::to_string(nth_allowed_cpu(n - 1))});
    if (n > 0 && std::size_t(n) <= p.programs.size() && !p.programs[std::size_t(n) - 1].empty()) {
        args.push_back("--");
        for (const std::string& a : p.programs[std::size_t(n) - 1]) args.push_back(a);
    }
    std::fflush(nullptr);
    const pid_t pid = fork();
    if (pid != 0) return pid;
    // The child: detached from this command's session and terminal input.
    setsid();
    const int in = open("/dev/null", O_RDONLY);
    if (in >= 0) dup2(in, 0);
    if (log_fd >= 0) {
        dup2(log_fd, 1);
        dup2(log_fd, 2);
    }
    sigset_t none;
    sigemptyset(&none);
    sigprocmask(SIG_SETMASK, &none, nullptr);
    std::vector<char*> argv;
    for (std::string& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    execvp(argv[0], argv.data());
    std::fprintf(stderr, "chimera: cannot run %s: %s\n", argv[0], std::strerror(errno));
    _exit(127);
}

}  // namespace

int cmd_start(const Options& o, const StartPlan& p) {
    if (p.programs.size() > std::size_t(p.rtpus)) {
        say("--program for RTPU %zu but only %d RTPUs are started (--rtpus) (see chimera --help)", p.programs.size(),
            p.rtpus);
        return 2;
    }
    bool created = false;
    struct stat ls{};
    if (lstat(o.backplane.c_str(), &ls) == 0) {
        // An existing file is checked whole before any RTPU starts on it
        // (refused here, once, not by every RTPU as it joins), and a
        // system already running on it is left alone: nothing is forked,
        // no log is opened.
        if (!file_fit_to_use(o.backplane)) return 1;
        std::string why;
        const std::string live = live_members(o.backplane, true, &why);
        if (!why.empty()) {
            say("%s: %s", o.backplane.c_str(), why.c_str());
            return 1;
        }
        if (!live.empty()) {
            say("the system on %s is already running (%s): nothing started; chimera status shows it, chimera stop "
                "stops it", o.backplane.c_str(), live.c_str());
            return 1;
        }
    } else {
        chm_bp_config_t cfg;
        chm_bp_config_init(&cfg);
        cfg.group = p.group;
        cfg.ring_records = 32;
        cfg.ring_record_size = 1024;  // a spawn request carries a path and arguments
        if (std::uint32_t(p.rtpus) + 2 > cfg.rtpu_slots) {
            say("--rtpus at most %u (see chimera --help)", cfg.rtpu_slots - 2);
            return 2;
        }
        if (int r = chm_bp_create(o.backplane.c_str(), &cfg)) {
            say("cannot create the backplane: %s (%s)", chm_bp_last_error(), std::strerror(-r));
            return 1;
        }
        created = true;
    }
    const std::string bin = find_rtpu_binary();
    // Slot 0 is the host server (extended file system, host calls, the
    // consoles' stdio), started first so the RTPUs' output finds it.
    const int first = p.host_server ? 0 : 1;
    std::vector<int> logs(std::size_t(p.rtpus) + 1, -1);
    for (int n = first; n <= p.rtpus && !p.log_terminal; ++n) {
        if ((logs[std::size_t(n)] = open_log(log_path(o.backplane, n))) >= 0) {
            // Appended after what an earlier run wrote: mark where this one starts.
            char line[96];
            const std::time_t now = std::time(nullptr);
            std::tm tm{};
            localtime_r(&now, &tm);
            const int k = int(std::strftime(line, sizeof line, "chimera start: %Y-%m-%d %H:%M:%S\n", &tm));
            if (k > 0) (void)!write(logs[std::size_t(n)], line, std::size_t(k));
            continue;
        }
        for (int fd : logs)
            if (fd >= 0) close(fd);
        if (created) unlink(o.backplane.c_str());
        return 1;
    }
    std::vector<pid_t> pids(std::size_t(p.rtpus) + 1, 0);
    for (int n = first; n <= p.rtpus; ++n) {
        pids[std::size_t(n)] = launch(o, p, n, bin, logs[std::size_t(n)]);
        if (logs[std::size_t(n)] >= 0) close(logs[std::size_t(n)]);
    }

    // Watch them come up: through the table and a ping each.
    std::string failure;
    if (int r = chm_bp_attach_host(o.backplane.c_str(), "chimera", nullptr)) {
        failure = std::string("cannot attach to watch the RTPUs: ") + chm_bp_last_error() + " (" +
                  std::strerror(-r) + ")";
    }
    chm_bp_status_t st;
    if (failure.empty() && chm_bp_status(&st) == 0 && std::uint32_t(p.rtpus) >= st.slots - 1)
        failure = "--rtpus " + std::to_string(p.rtpus) + " needs more slots than the backplane's " +
                  std::to_string(st.slots);
    const double limit = o.timeout_s < 0 ? 10.0 : o.timeout_s;
    const std::uint64_t end = mono_ms() + std::uint64_t(limit * 1000);
    std::vector<bool> ready(pids.size(), false);
    chm_rtpu_timeout_set(200'000'000);
    bool warned = false;
    for (int waiting = p.rtpus + 1 - first; failure.empty() && waiting > 0;) {
        for (int n = first; n <= p.rtpus && failure.empty(); ++n) {
            if (ready[std::size_t(n)]) continue;
            int ws = 0;
            if (waitpid(pids[std::size_t(n)], &ws, WNOHANG) == pids[std::size_t(n)]) {
                pids[std::size_t(n)] = 0;
                std::string why = p.log_terminal ? "" : last_line(log_path(o.backplane, n));
                if (why.empty())
                    why = WIFSIGNALED(ws) ? std::string("killed by ") + strsignal(WTERMSIG(ws))
                                          : "exit status " + std::to_string(WEXITSTATUS(ws));
                failure = (n ? "RTPU " + std::to_string(n) : std::string("the host server")) + " failed to start: " + why;
                break;
            }
            (void)chm_bp_status(&st);
            const chm_bp_slot_info_t& s = st.slot[n];
            if (s.state != CHM_BP_RUNNING || s.pid != pids[std::size_t(n)]) continue;
            const int ping = chm_rtpu_ping(n, nullptr);
            if (ping == -EMSGSIZE && !warned) {  // an existing backplane with small rings
                say("warning: %s: no express mail on this backplane (status cannot list tasks)",
                    chm_rtpu_last_error());
                warned = true;
            }
            if (ping == 0 || ping == -EMSGSIZE) {
                ready[std::size_t(n)] = true;
                --waiting;
            }
        }
        if (!failure.empty() || waiting == 0) break;
        if (mono_ms() >= end) {
            failure = "RTPUs not running within " + std::to_string(limit) + " s";
            break;
        }
        nap_ms(20);
    }
    if (failure.empty()) {
        std::printf("started %d RTPU%s on %s:", p.rtpus, p.rtpus == 1 ? "" : "s", o.backplane.c_str());
        for (int n = 1; n <= p.rtpus; ++n) std::printf(" %d (pid %d)", n, int(pids[std::size_t(n)]));
        std::printf("\n");
        if (p.host_server)
            std::printf("host server: pid %d, files beneath %s; chimera console attaches a terminal\n",
                        int(pids[0]), p.host_root.c_str());
        if (!p.log_terminal) std::printf("logs: %s\n", log_path(o.backplane, 1).c_str());
        std::fflush(stdout);
        (void)chm_bp_leave();
        return 0;
    }
    // All or nothing: stop what we started, remove what we created. These
    // are our own children (pids from fork, reaped here), not table pids.
    say("%s", failure.c_str());
    for (pid_t pid : pids)
        if (pid > 0) kill(pid, SIGTERM);
    const std::uint64_t kend = mono_ms() + 3000;
    for (pid_t pid : pids) {
        if (pid <= 0) continue;
        while (waitpid(pid, nullptr, WNOHANG) == 0 && mono_ms() < kend) nap_ms(10);
        if (kill(pid, 0) == 0) {
            kill(pid, SIGKILL);
            waitpid(pid, nullptr, 0);
        }
    }
    (void)chm_bp_leave();
    if (created) {
        unlink(o.backplane.c_str());
        for (int n = first; n <= p.rtpus; ++n) unlink(log_path(o.backplane, n).c_str());
    }
    return 1;
}

}  // namespace chimera_cmd
