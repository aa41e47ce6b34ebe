// chimera: start, watch, operate, stop and remove a whole Chimera system
// on one backplane (docs/backplane.md, "RTPU processes and express mail").
// This file parses the command line; each subcommand lives in its own
// file (cmd.hpp).
//
//   chimera start   [--backplane PATH] [--rtpus N] [--program RTPU:PATH[:ARG...]]...
//                   [--policy P] [--rt-priority P] [--pin] [--lock-memory]
//                   [--idle-poll US] [--timer-lead US|auto] [--log-terminal] [--timeout S]
//                   [--group NAME] [--programs DIR]...
//   chimera status  [--backplane PATH] [--watch [--interval S] [--count N | --once]]
//   chimera load    [--backplane PATH] RTPU PROGRAM [ARG...]
//   chimera kill    [--backplane PATH] RTPU TASK
//   chimera objects [--backplane PATH]
//   chimera stop    [--backplane PATH] [--rtpu N] [--timeout S]
//   chimera rm      [--backplane PATH] [--force]
//   chimera path    [--backplane PATH]
//   chimera svar    [--backplane PATH] list | get | set | declare | plan ...
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
        "usage: chimera start   [--backplane PATH] [--rtpus N] [--program RTPU:PATH[:ARG...]]...\n"
        "                       [--policy muf|rm|edf|mlf|fixed] [--rt-priority P] [--pin]\n"
        "                       [--lock-memory] [--idle-poll US] [--timer-lead US|auto]\n"
        "                       [--orphan-output log|drop]\n"
        "                       [--log-terminal] [--timeout S]\n"
        "                       [--group NAME] [--programs DIR]... [--host-root DIR]\n"
        "                       [--no-host-server] [--host-allow-shell]\n"
        "       chimera status  [--backplane PATH] [--watch [--interval S] [--count N | --once]]\n"
        "       chimera load    [--backplane PATH] RTPU PROGRAM [ARG...]\n"
        "       chimera kill    [--backplane PATH] RTPU TASK\n"
        "       chimera objects [--backplane PATH]\n"
        "       chimera stop    [--backplane PATH] [--rtpu N] [--timeout S]\n"
        "       chimera rm      [--backplane PATH] [--force]\n"
        "       chimera path    [--backplane PATH]\n"
        "       chimera console [--backplane PATH] [--rtpus N,M...] [--script FILE]\n"
        "       chimera svar    [--backplane PATH] list | get NAME | set NAME V... |\n"
        "                       declare NAME TYPE RxC [UNIT] | plan CONFIG\n"
        "\n"
        "start   create the backplane PATH if absent (default $%s, else\n"
        "        backplane.bp in $XDG_RUNTIME_DIR/chimera or /dev/shm/chimera-<uid>,\n"
        "        a directory of yours alone) and start RTPUs 1..N (default 2) as\n"
        "        chimera-rtpu processes, each with the programs given for it; their\n"
        "        output is appended to PATH.rtpuN.log (or this terminal with\n"
        "        --log-terminal). An existing backplane is validated first, and a\n"
        "        system already running on it is refused (nothing started, no log\n"
        "        touched). Waits up to S seconds (default 10) until every RTPU runs\n"
        "        and answers. --rt-priority, --lock-memory, --idle-poll, --timer-lead and\n"
        "        --orphan-output log|drop (tasks' lines while no console owns their\n"
        "        RTPU: to its log, the default, or dropped) go to every\n"
        "        RTPU (see chimera-rtpu --help); --pin runs RTPU n on the n-th allowed\n"
        "        CPU (round robin). --group NAME makes a new backplane mode 0660 for\n"
        "        that group, whose members may then attach; --programs DIR (any\n"
        "        number) lets the RTPUs load programs only from under those\n"
        "        directories (otherwise: files that only you or root can change).\n"
        "        A backplane that is a link, not a regular file, not yours, or\n"
        "        writable by others is refused (see SECURITY.md). The host server\n"
        "        (slot 0, log PATH.host.log) serves tasks' host files beneath DIR\n"
        "        (--host-root, default the current directory) and host calls, and\n"
        "        carries their stdio to `chimera console`; --no-host-server leaves\n"
        "        it out (tasks' output then stays in the RTPU logs)\n"
        "status  the RTPU table and each running RTPU's tasks (through express mail):\n"
        "        CPU share, cycles, misses, worst lateness past the deadline, worst\n"
        "        CPU of one cycle, stack high-water mark; per RTPU the utilisation of\n"
        "        its periodic tasks and of its MUF critical set (mean and worst CPU\n"
        "        per cycle over the period). --watch redraws it in place every S\n"
        "        seconds (--interval, default 1) until q or Ctrl-C, or N times\n"
        "        (--count N; --once is --count 1)\n"
        "load    load the control program PROGRAM (a shared object with a main,\n"
        "        chimera/program.h) on RTPU (its number or name) and start its main\n"
        "        with the ARGs (argv[0] = the program's absolute path); prints the\n"
        "        task id\n"
        "kill    destroy task TASK (its id, or its name) of RTPU\n"
        "objects every named object of the backplane: message queues (fill and\n"
        "        waiters), remote semaphores (value and waiters), shared memory\n"
        "        segments, and the state variables\n"
        "stop    SIGTERM every RTPU, wait up to S seconds (default 5), SIGKILL the rest;\n"
        "        --rtpu N stops that RTPU only (by express mail: its shutdown hooks run;\n"
        "        SIGTERM, then SIGKILL, if it does not go within S seconds)\n"
        "rm      remove the backplane file and its RTPU logs; refuses while processes\n"
        "        are attached or when the file is not a backplane, unless --force\n"
        "path    print the backplane path these commands use (for scripts)\n"
        "console a terminal for the RTPUs given (default: every one no other console\n"
        "        owns): their tasks' output, lines prefixed [N]; commands load, tasks,\n"
        "        kill, stop, fg, rtpus, help, source, history, quit (line editing and\n"
        "        history, a mistyped command gets the closest match); one RTPU owns\n"
        "        stdin (fg N): the next line typed while its task reads goes to it,\n"
        "        a reader on another RTPU waits (\"Waiting for TTY Input\"); --script\n"
        "        runs FILE's commands first\n"
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
    static const char* const kCommands[] = {"start", "status", "load", "kill", "objects", "stop", "rm", "path", "svar", "console"};
    bool known = false;
    for (const char* c : kCommands) known = known || cmd == c;
    if (!known)
        bad("unknown command \"" + cmd + "\" (start, status, load, kill, objects, stop, rm, path, svar or console)");
    // Positional words: svar's subcommand and its arguments; load's RTPU,
    // PROGRAM and ARGs (everything after PROGRAM goes to the program, also
    // words that look like options); kill's RTPU and TASK.
    std::vector<const char*> words;
    Options o;
    StartPlan plan;
    std::vector<const char*> programs;
    const char* backplane = nullptr;
    for (int i = 2; i < argc; ++i) {
        const std::string a = argv[i];
        if (cmd == "console" && a != "--backplane") {
            words.push_back(argv[i]);  // console's own options (--rtpus, --script)
            if ((a == "--rtpus" || a == "--script") && i + 1 < argc) words.push_back(argv[++i]);
            continue;
        }
        if (cmd == "load" && words.size() >= 2) {
            words.push_back(argv[i]);  // the program's own arguments
            continue;
        }
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
        } else if (a == "--timeout" && (cmd == "start" || cmd == "stop")) {
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
        } else if (a == "--timer-lead" && starting) {
            const char* v = value();
            long n = 0;
            if (std::string(v) != "auto" && !parse_num(v, 0, 1000, &n))
                bad("--timer-lead wants microseconds 0..1000 or auto, not \"" + std::string(v) + "\"");
            plan.rtpu_options.insert(plan.rtpu_options.end(), {a, v});
        } else if (a == "--lock-memory" && starting) {
            plan.rtpu_options.push_back(a);
        } else if (a == "--orphan-output" && starting) {
            const char* v = value();
            if (std::string(v) != "log" && std::string(v) != "drop")
                bad("--orphan-output wants log or drop, not \"" + std::string(v) + "\"");
            plan.rtpu_options.insert(plan.rtpu_options.end(), {a, v});
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
        } else if (a == "--host-root" && starting) {
            const char* v = value();
            char real[PATH_MAX];
            struct stat st{};
            if (!realpath(v, real) || stat(real, &st) != 0) {
                say("--host-root %s: %s", v, std::strerror(errno));
                return 1;
            }
            if (!S_ISDIR(st.st_mode)) bad(std::string("--host-root ") + v + ": not a directory");
            plan.host_root = real;
        } else if (a == "--no-host-server" && starting) {
            plan.host_server = false;
        } else if (a == "--host-allow-shell" && starting) {
            plan.allow_shell = true;
        } else if (a == "--force" && cmd == "rm") {
            o.force = true;
        } else if (a == "--rtpu" && cmd == "stop") {
            const char* v = value();
            long n = 0;
            if (!parse_num(v, 1, 31, &n)) bad(std::string("--rtpu wants an RTPU number 1..31, not \"") + v + "\"");
            o.rtpu = int(n);
        } else if (a == "--watch" && cmd == "status") {
            o.watch = true;
        } else if (a == "--interval" && cmd == "status") {
            const char* v = value();
            char* end = nullptr;
            o.interval_s = std::strtod(v, &end);
            if (!*v || *end || !(o.interval_s >= 0.1) || o.interval_s > 3600)
                bad(std::string("--interval wants seconds 0.1..3600, not \"") + v + "\"");
        } else if (a == "--count" && cmd == "status") {
            const char* v = value();
            if (!parse_num(v, 1, 1000000, &o.count)) bad(std::string("--count wants 1..1000000, not \"") + v + "\"");
        } else if (a == "--once" && cmd == "status") {
            o.count = 1;
        } else if ((cmd == "svar" || cmd == "load" || cmd == "kill") && a.rfind("--", 0) != 0) {
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
        if (plan.programs.size() > std::size_t(plan.rtpus))
            bad("--program for RTPU " + std::to_string(plan.programs.size()) + " but only " +
                std::to_string(plan.rtpus) + " RTPUs are started (--rtpus)");
        if (plan.host_root.empty()) {
            char cwd[PATH_MAX];
            if (!getcwd(cwd, sizeof cwd)) {
                say("cannot read the current directory (the host server's root): %s", std::strerror(errno));
                return 1;
            }
            plan.host_root = cwd;
        }
        return cmd_start(o, plan);
    }
    if (cmd == "path") {
        std::printf("%s\n", o.backplane.c_str());
        return 0;
    }
    if ((o.count || o.interval_s != 1.0) && !o.watch) bad("--interval, --count and --once go with status --watch");
    if (cmd == "load" && words.size() < 2) bad("load wants RTPU PROGRAM [ARG...]");
    if (cmd == "kill" && words.size() != 2) bad("kill wants RTPU TASK (a task id or name)");
    if (cmd == "status") return cmd_status(o);
    if (cmd == "console") return cmd_console(o, words);
    if (cmd == "load") return cmd_load(o, words);
    if (cmd == "kill") return cmd_kill(o, words);
    if (cmd == "objects") return cmd_objects(o);
    if (cmd == "stop" && o.rtpu > 0) return cmd_stop_one(o);
    if (cmd == "svar") return cmd_svar(o, words);
    if (cmd == "stop") return cmd_stop(o);
    return cmd_rm(o);
}
