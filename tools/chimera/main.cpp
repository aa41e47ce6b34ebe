// chimera: start, show, stop and remove a whole Chimera system on one
// backplane (docs/backplane.md, "RTPU processes and express mail").
//
//   chimera start  [--backplane PATH] [--rtpus N] [--program RTPU:PATH[:ARG...]]...
//                  [--policy P] [--rt-priority P] [--pin] [--lock-memory]
//                  [--idle-poll US] [--log-terminal] [--timeout S]
//                  [--group NAME] [--programs DIR]...
//   chimera status [--backplane PATH]
//   chimera stop   [--backplane PATH] [--timeout S]
//   chimera rm     [--backplane PATH] [--force]
//   chimera path   [--backplane PATH]
//
// start creates the backplane if absent and starts RTPUs 1..N as detached
// chimera-rtpu processes (own session, stdin /dev/null, output to
// PATH.rtpuN.log unless --log-terminal), then waits (bounded) until each
// is RUNNING in the table and answers express mail. If any fails, the ones
// it started are stopped and a backplane it created is removed.
#include <cerrno>
#include <climits>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include <fcntl.h>
#include <grp.h>
#include <sched.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "chimera/bp.h"
#include "chimera/rtpu.h"
#include "cmd.hpp"
#include "../parse_num.hpp"

using namespace chimera_cmd;
using chimera_tools::parse_num;

namespace {

void usage(FILE* f) {
    std::fprintf(f,
        "usage: chimera start  [--backplane PATH] [--rtpus N] [--program RTPU:PATH[:ARG...]]...\n"
        "                      [--policy muf|rm|edf|mlf|fixed] [--rt-priority P] [--pin]\n"
        "                      [--lock-memory] [--idle-poll US] [--log-terminal] [--timeout S]\n"
        "                      [--group NAME] [--programs DIR]...\n"
        "       chimera status [--backplane PATH]\n"
        "       chimera stop   [--backplane PATH] [--timeout S]\n"
        "       chimera rm     [--backplane PATH] [--force]\n"
        "       chimera path   [--backplane PATH]\n"
        "       chimera svar   [--backplane PATH] list | get NAME | set NAME V... |\n"
        "                      declare NAME TYPE RxC [UNIT] | plan CONFIG\n"
        "\n"
        "start   create the backplane PATH if absent (default $%s, else\n"
        "        backplane.bp in $XDG_RUNTIME_DIR/chimera or /dev/shm/chimera-<uid>,\n"
        "        a directory of yours alone) and start RTPUs 1..N (default 2) as\n"
        "        chimera-rtpu processes, each with the programs given for it; their\n"
        "        output goes to PATH.rtpuN.log (or this terminal with --log-terminal).\n"
        "        Waits up to S seconds (default 10) until every RTPU runs and answers.\n"
        "        --rt-priority, --lock-memory and --idle-poll go to every RTPU (see\n"
        "        chimera-rtpu --help); --pin runs RTPU n on the n-th allowed CPU\n"
        "        (round robin). --group NAME makes a new backplane mode 0660 for\n"
        "        that group, whose members may then attach; --programs DIR (any\n"
        "        number) lets the RTPUs load programs only from under those\n"
        "        directories (otherwise: files that only you or root can change).\n"
        "        A backplane that is a link, not a regular file, not yours, or\n"
        "        writable by others is refused (see SECURITY.md).\n"
        "status  the RTPU table and each running RTPU's tasks (through express mail)\n"
        "stop    SIGTERM every RTPU, wait up to S seconds (default 5), SIGKILL the rest\n"
        "rm      remove the backplane file and its RTPU logs; refuses while processes\n"
        "        are attached or when the file is not a backplane, unless --force\n"
        "path    print the backplane path these commands use (for scripts)\n"
        "svar    the state-variable table: list every variable with its writer and\n"
        "        value, get one, set a set-point (refused while a module writes it),\n"
        "        or declare one (TYPE double, float, int32, uint32 or bool; shape\n"
        "        RxC, 6x1 for a vector of 6); plan CONFIG prints the bytes each\n"
        "        module of a system's configuration file copies per cycle and per\n"
        "        second, per RTPU and in all (see chimera/servo.h, \"Systems\")\n",
        CHM_BP_ENV);
}

[[noreturn]] void bad(const std::string& msg) {
    say("%s (see chimera --help)", msg.c_str());
    std::exit(2);
}

struct StartPlan {
    int rtpus = 2;
    std::string policy;
    std::vector<std::string> rtpu_options;  // given to every chimera-rtpu
    bool pin = false;
    bool log_terminal = false;
    int group = -1;  // gid for a new backplane
    std::vector<std::vector<std::string>> programs;  // per RTPU: chimera-rtpu's program arguments
};

// "RTPU:PATH[:ARG...]": path made absolute (the RTPU may not share our
// working directory for long), arguments split at ':'.
void add_program(StartPlan* p, const char* spec) {
    const std::string s(spec);
    const std::size_t c1 = s.find(':');
    long n = 0;
    if (c1 == std::string::npos || !parse_num(s.substr(0, c1).c_str(), 1, 1000, &n))
        bad("--program wants RTPU:PATH[:ARG...], not \"" + s + "\"");
    std::vector<std::string> parts;
    std::size_t at = c1 + 1;
    for (;;) {
        const std::size_t c = s.find(':', at);
        parts.push_back(s.substr(at, c == std::string::npos ? std::string::npos : c - at));
        if (c == std::string::npos) break;
        at = c + 1;
    }
    if (parts[0].empty()) bad("--program " + s + ": no program path");
    char real[PATH_MAX];
    if (!realpath(parts[0].c_str(), real)) {
        say("--program %s: %s: %s", spec, parts[0].c_str(), std::strerror(errno));
        std::exit(1);
    }
    parts[0] = real;
    if (std::size_t(n) > p->programs.size()) p->programs.resize(std::size_t(n));
    auto& list = p->programs[std::size_t(n) - 1];
    if (!list.empty()) list.push_back("--");
    for (const std::string& a : parts) list.push_back(a);
}

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
    if (!p.policy.empty()) args.insert(args.end(), {"--policy", p.policy});
    args.insert(args.end(), p.rtpu_options.begin(), p.rtpu_options.end());
    if (p.pin) args.insert(args.end(), {"--cpu", std::to_string(nth_allowed_cpu(n - 1))});
    if (std::size_t(n) <= p.programs.size() && !p.programs[std::size_t(n) - 1].empty()) {
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

int cmd_start(const Options& o, const StartPlan& p) {
    if (p.programs.size() > std::size_t(p.rtpus))
        bad("--program for RTPU " + std::to_string(p.programs.size()) + " but only " + std::to_string(p.rtpus) +
            " RTPUs are started (--rtpus)");
    bool created = false;
    struct stat ls{};
    if (lstat(o.backplane.c_str(), &ls) == 0) {
        // An existing file is checked before any RTPU starts on it:
        // refused here, once, not by every RTPU as it joins.
        if (!file_fit_to_use(o.backplane)) return 1;
    } else {
        chm_bp_config_t cfg;
        chm_bp_config_init(&cfg);
        cfg.group = p.group;
        cfg.ring_records = 32;
        cfg.ring_record_size = 1024;  // a spawn request carries a path and arguments
        if (std::uint32_t(p.rtpus) + 2 > cfg.rtpu_slots) bad("--rtpus at most " + std::to_string(cfg.rtpu_slots - 2));
        if (int r = chm_bp_create(o.backplane.c_str(), &cfg)) {
            say("cannot create the backplane: %s (%s)", chm_bp_last_error(), std::strerror(-r));
            return 1;
        }
        created = true;
    }
    const std::string bin = find_rtpu_binary();
    std::vector<int> logs(std::size_t(p.rtpus) + 1, -1);
    for (int n = 1; n <= p.rtpus && !p.log_terminal; ++n) {
        if ((logs[std::size_t(n)] = open_log(log_path(o.backplane, n))) >= 0) continue;
        for (int fd : logs)
            if (fd >= 0) close(fd);
        if (created) unlink(o.backplane.c_str());
        return 1;
    }
    std::vector<pid_t> pids(std::size_t(p.rtpus) + 1, 0);
    for (int n = 1; n <= p.rtpus; ++n) {
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
    for (int waiting = p.rtpus; failure.empty() && waiting > 0;) {
        for (int n = 1; n <= p.rtpus && failure.empty(); ++n) {
            if (ready[std::size_t(n)]) continue;
            int ws = 0;
            if (waitpid(pids[std::size_t(n)], &ws, WNOHANG) == pids[std::size_t(n)]) {
                pids[std::size_t(n)] = 0;
                std::string why = p.log_terminal ? "" : last_line(log_path(o.backplane, n));
                if (why.empty())
                    why = WIFSIGNALED(ws) ? std::string("killed by ") + strsignal(WTERMSIG(ws))
                                          : "exit status " + std::to_string(WEXITSTATUS(ws));
                failure = "RTPU " + std::to_string(n) + " failed to start: " + why;
                break;
            }
            chm_bp_status(&st);
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
        if (!p.log_terminal) std::printf("logs: %s\n", log_path(o.backplane, 1).c_str());
        std::fflush(stdout);
        chm_bp_leave();
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
    chm_bp_leave();
    if (created) {
        unlink(o.backplane.c_str());
        for (int n = 1; n <= p.rtpus; ++n) unlink(log_path(o.backplane, n).c_str());
    }
    return 1;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc < 2) {
        usage(stderr);
        return 2;
    }
    const std::string cmd = argv[1];
    if (cmd == "--help" || cmd == "-h" || cmd == "help") {
        usage(stdout);
        return 0;
    }
    if (cmd != "start" && cmd != "status" && cmd != "stop" && cmd != "rm" && cmd != "path" && cmd != "svar")
        bad("unknown command \"" + cmd + "\" (start, status, stop, rm, path or svar)");
    std::vector<const char*> words;  // svar's subcommand and its arguments
    Options o;
    StartPlan plan;
    std::vector<const char*> programs;
    const char* backplane = nullptr;
    for (int i = 2; i < argc; ++i) {
        const std::string a = argv[i];
        auto value = [&]() -> const char* {
            if (i + 1 >= argc) bad("option " + a + " needs a value");
            return argv[++i];
        };
        const bool starting = cmd == "start";
        if (a == "--help" || a == "-h") {
            usage(stdout);
            return 0;
        } else if (a == "--backplane") {
            backplane = value();
            if (!*backplane) bad("--backplane needs a path");
        } else if (a == "--timeout" && cmd != "status" && cmd != "rm") {
            const char* v = value();
            char* end = nullptr;
            o.timeout_s = std::strtod(v, &end);
            if (!*v || *end || !(o.timeout_s > 0) || o.timeout_s > 3600)
                bad(std::string("--timeout wants seconds (0..3600], not \"") + v + "\"");
        } else if (a == "--rtpus" && starting) {
            const char* v = value();
            long n = 0;
            if (!parse_num(v, 1, 30, &n)) bad(std::string("--rtpus wants 1..30, not \"") + v + "\"");
            plan.rtpus = int(n);
        } else if (a == "--program" && starting) {
            programs.push_back(value());
        } else if (a == "--policy" && starting) {
            plan.policy = value();
            if (plan.policy != "muf" && plan.policy != "rm" && plan.policy != "edf" && plan.policy != "mlf" &&
                plan.policy != "fixed")
                bad("unknown policy \"" + plan.policy + "\" (muf, rm, edf, mlf or fixed)");
        } else if ((a == "--rt-priority" || a == "--idle-poll") && starting) {
            const char* v = value();
            long n = 0;
            if (a == "--rt-priority" ? !parse_num(v, 1, 99, &n) : !parse_num(v, 0, 100000, &n))
                bad(a + (a == "--rt-priority" ? " wants a SCHED_FIFO priority 1..99" : " wants microseconds 0..100000") +
                    ", not \"" + v + "\"");
            plan.rtpu_options.insert(plan.rtpu_options.end(), {a, v});
        } else if (a == "--lock-memory" && starting) {
            plan.rtpu_options.push_back(a);
        } else if (a == "--pin" && starting) {
            plan.pin = true;
        } else if (a == "--group" && starting) {
            const char* v = value();
            const group* g = getgrnam(v);
            if (!g) bad(std::string("--group: no group \"") + v + "\"");
            plan.group = int(g->gr_gid);
        } else if (a == "--programs" && starting) {
            const char* v = value();
            char real[PATH_MAX];
            struct stat st{};
            if (!realpath(v, real) || stat(real, &st) != 0) {
                say("--programs %s: %s", v, std::strerror(errno));
                return 1;
            }
            if (!S_ISDIR(st.st_mode)) bad(std::string("--programs ") + v + ": not a directory");
            plan.rtpu_options.insert(plan.rtpu_options.end(), {"--programs", real});
        } else if (a == "--log-terminal" && starting) {
            plan.log_terminal = true;
        } else if (a == "--force" && cmd == "rm") {
            o.force = true;
        } else if (cmd == "svar" && a.rfind("--", 0) != 0) {
            words.push_back(argv[i]);  // "-1.5" is a value; options start with --
        } else {
            bad("chimera " + cmd + ": unknown option " + a);
        }
    }
    if (backplane) {
        o.backplane = backplane;
    } else {
        char path[4096];
        if (chm_bp_default_path(path, sizeof path) != 0) bad("default backplane path too long");
        o.backplane = path;
    }
    if (cmd == "start") {
        // Root is never a reason in itself (SECURITY.md): say what suffices.
        if (geteuid() == 0 && !std::getenv("CHIMERA_AS_ROOT"))
            std::fprintf(stderr,
                         "chimera: warning: running as root is not needed: real-time priority needs only "
                         "CAP_SYS_NICE or an rtprio limit, --lock-memory CAP_IPC_LOCK or a memlock limit "
                         "(README, \"Privileges\"); RTPUs drop every capability once set up. "
                         "Set CHIMERA_AS_ROOT=1 to silence this when root is deliberate.\n");
        for (const char* spec : programs) add_program(&plan, spec);
        return cmd_start(o, plan);
    }
    if (cmd == "path") {
        std::printf("%s\n", o.backplane.c_str());
        return 0;
    }
    if (cmd == "status") return cmd_status(o);
    if (cmd == "svar") return cmd_svar(o, words);
    if (cmd == "stop") return cmd_stop(o);
    return cmd_rm(o);
}
