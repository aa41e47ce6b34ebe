// chimera-rtpu: one RTPU of a Chimera system. Joins the backplane as RTPU
// N, runs the kernel with the express-mail server task, loads the control
// programs named on the command line (each main a task) and runs until it
// is told to stop: SIGTERM, SIGINT or SIGHUP (read through a signalfd bound
// to an interrupt line, whose handler wakes a shutdown task that calls
// chm_kernel_stop, so shutdown hooks run in task context), or an express
// mail stop request. Then it leaves the backplane and exits 0.
//
// Control programs resolve the chm_* calls against this executable (it
// carries the whole of libchimera and exports it).
#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include <poll.h>
#include <sys/signalfd.h>
#include <sys/stat.h>
#include <unistd.h>

#include "chimera/bp.h"
#include "chimera/chimera.h"
#include "chimera/rtpu.h"
#include "ipc/wake/wake.hpp"
#include "host/console.hpp"
#include "host/server/server.hpp"
#include "ipc/xmail/xmail.hpp"
#include "port.hpp"
#include "realtime.hpp"
#include "../parse_num.hpp"

namespace {

constexpr int kSignalLine = 63;          // the last IRQ line: programs start from 32
constexpr int kServerPriority = 1000;    // above ordinary aperiodic work
constexpr int kShutdownPriority = 10000;
constexpr int kStdioPriority = 1;        // below every control program's task

void usage(FILE* f) {
    std::fprintf(f,
        "usage: chimera-rtpu [--backplane PATH] --rtpu N [--name NAME]\n"
        "                    [--policy muf|rm|edf|mlf|fixed] [--idle-poll US]\n"
        "                    [--timer-lead US|auto]\n"
        "                    [--rt-priority P] [--cpu K] [--lock-memory]\n"
        "                    [--programs DIR]... [--]\n"
        "                    [PROGRAM.so [ARG...] [-- PROGRAM.so [ARG...]]...]\n"
        "\n"
        "Joins the backplane PATH (default $%s, else backplane.bp in\n"
        "$XDG_RUNTIME_DIR/chimera or /dev/shm/chimera-<uid>) as\n"
        "RTPU N (1..slots-1), starts the kernel and its express-mail server, loads\n"
        "each control program (a shared object with a main) and starts its main as\n"
        "a task with argv[0] = the program's path. Programs are separated by '--'.\n"
        "Runs until SIGTERM, SIGINT or SIGHUP (shutdown hooks run, the RTPU leaves\n"
        "the backplane, exit 0) or an express-mail stop request (exit with its code).\n"
        "\n"
        "--idle-poll US    with nothing to run, poll the mailbox US microseconds\n"
        "                  before sleeping (0..100000, default 0): a wake-up from a\n"
        "                  busy peer then costs no system call\n"
        "--timer-lead US|auto  an idle RTPU wakes US microseconds (0..1000) ahead of\n"
        "                  its next timer event and polls until it is due: releases\n"
        "                  start on time, not one host wake-up latency late. auto\n"
        "                  (default) learns the host's latency; 0 turns it off\n"
        "--rt-priority P   run the process at SCHED_FIFO priority P (needs\n"
        "                  CAP_SYS_NICE or an rtprio limit)\n"
        "--cpu K           run only on CPU K\n"
        "--lock-memory     mlockall: no page fault in a control loop\n"
        "--host-server ROOT  be the host server (slot 0, --rtpu 0 implied): serve the\n"
        "                  extended file system beneath ROOT and host procedure\n"
        "                  calls to every RTPU's tasks (chimera/xfs.h, host.h)\n"
        "--host-allow-shell  let chm_host_run start a shell (sh, bash...)\n"
        "--stdio-log       tasks' stdout and stderr go straight to this process's\n"
        "                  (the log); by default they go line by line through the\n"
        "                  host server to the console that owns this RTPU, and\n"
        "                  stdin reads come from that console\n"
        "--orphan-output log|drop  what becomes of tasks' lines while no console\n"
        "                  owns this RTPU: written to the log (default) or dropped\n"
        "--programs DIR    load programs (here and by express mail) only from under\n"
        "                  DIR (any number); without it, only files that no one but\n"
        "                  you or root can change (SECURITY.md)\n"
        "\n"
        "Exit 2: bad arguments; 1: cannot join, initialise or load a program, or\n"
        "the OS refused --rt-priority, --cpu or --lock-memory.\n",
        CHM_BP_ENV);
}

struct Program {
    std::string path;
    std::vector<std::string> args;  // argv[0] is the path
};

struct Options {
    const char* backplane = nullptr;
    int rtpu = -1;
    const char* name = nullptr;
    chm_sched_policy policy = CHM_SCHED_MUF;
    int idle_poll_us = 0;
    int timer_lead_us = -1;  // -1: automatic (CHM_TIMER_LEAD_AUTO)
    chimera_rtpu::HostRealtime realtime;
    std::vector<Program> programs;
    std::vector<const char*> program_dirs;  // --programs
    const char* host_root = nullptr;        // --host-server: serve the host from slot 0
    bool allow_shell = false;               // --host-allow-shell
    bool console_stdio = true;              // --stdio-log: false
    bool drop_orphans = false;              // --orphan-output drop
};

[[noreturn]] void bad(const char* fmt, const char* arg) {
    std::fprintf(stderr, "chimera-rtpu: ");
    std::fprintf(stderr, fmt, arg);
    std::fprintf(stderr, " (see chimera-rtpu --help)\n");
    std::exit(2);
}

bool parse_int(const char* s, int* out) {
    long v = 0;
    if (!chimera_tools::parse_num(s, 0, 1000000, &v)) return false;
    *out = int(v);
    return true;
}

Options parse(int argc, char** argv) {
    Options o;
    int i = 1;
    auto value = [&](const char* opt) -> const char* {
        if (i + 1 >= argc) bad("option %s needs a value", opt);
        return argv[++i];
    };
    for (; i < argc; ++i) {
        const char* a = argv[i];
        if (!std::strcmp(a, "--help") || !std::strcmp(a, "-h")) {
            usage(stdout);
            std::exit(0);
        } else if (!std::strcmp(a, "--backplane")) {
            o.backplane = value(a);
        } else if (!std::strcmp(a, "--rtpu")) {
            const char* v = value(a);
            if (!parse_int(v, &o.rtpu)) bad("--rtpu wants an RTPU number, not \"%s\"", v);
        } else if (!std::strcmp(a, "--name")) {
            o.name = value(a);
            if (!*o.name || std::strlen(o.name) > CHM_BP_NAME_MAX) bad("--name \"%s\" must have 1..31 characters", o.name);
        } else if (!std::strcmp(a, "--policy")) {
            const char* v = value(a);
            static const struct { const char* n; chm_sched_policy p; } kPol[] = {
                {"muf", CHM_SCHED_MUF}, {"rm", CHM_SCHED_RM}, {"edf", CHM_SCHED_EDF},
                {"mlf", CHM_SCHED_MLF}, {"fixed", CHM_SCHED_FIXED}};
            bool found = false;
            for (const auto& p : kPol)
                if (!std::strcmp(v, p.n)) o.policy = p.p, found = true;
            if (!found) bad("unknown policy \"%s\" (muf, rm, edf, mlf or fixed)", v);
        } else if (!std::strcmp(a, "--idle-poll")) {
            const char* v = value(a);
            if (!parse_int(v, &o.idle_poll_us) || o.idle_poll_us > 100000)
                bad("--idle-poll wants microseconds 0..100000, not \"%s\"", v);
        } else if (!std::strcmp(a, "--timer-lead")) {
            const char* v = value(a);
            if (!std::strcmp(v, "auto")) o.timer_lead_us = -1;
            else if (!parse_int(v, &o.timer_lead_us) || o.timer_lead_us > 1000)
                bad("--timer-lead wants microseconds 0..1000 or auto, not \"%s\"", v);
        } else if (!std::strcmp(a, "--rt-priority")) {
            const std::string why = chimera_rtpu::parse_fifo_priority(value(a), &o.realtime.fifo_priority);
            if (!why.empty()) bad("%s", why.c_str());
        } else if (!std::strcmp(a, "--cpu")) {
            const std::string why = chimera_rtpu::parse_cpu(value(a), &o.realtime.cpu);
            if (!why.empty()) bad("%s", why.c_str());
        } else if (!std::strcmp(a, "--programs")) {
            const char* v = value(a);
            struct stat st;
            if (::stat(v, &st) != 0 || !S_ISDIR(st.st_mode)) bad("--programs \"%s\": not a directory", v);
            o.program_dirs.push_back(v);
        } else if (!std::strcmp(a, "--lock-memory")) {
            o.realtime.lock_memory = true;
        } else if (!std::strcmp(a, "--host-server")) {
            const char* v = value(a);
            struct stat st;
            if (::stat(v, &st) != 0 || !S_ISDIR(st.st_mode)) bad("--host-server \"%s\": not a directory", v);
            o.host_root = v;
            if (o.rtpu < 0) o.rtpu = 0;
        } else if (!std::strcmp(a, "--host-allow-shell")) {
            o.allow_shell = true;
        } else if (!std::strcmp(a, "--stdio-log")) {
            o.console_stdio = false;
        } else if (!std::strcmp(a, "--orphan-output")) {
            const char* v = value(a);
            if (std::strcmp(v, "log") && std::strcmp(v, "drop")) bad("--orphan-output \"%s\": log or drop", v);
            o.drop_orphans = !std::strcmp(v, "drop");
        } else if (!std::strcmp(a, "--")) {
            ++i;
            break;
        } else if (a[0] == '-') {
            bad("unknown option %s", a);
        } else {
            break;
        }
    }
    if (o.rtpu < 0) bad("%s", "--rtpu N is required");
    if (o.rtpu == 0 && !o.host_root) bad("%s", "RTPU 0 is the host server's slot (--host-server ROOT); RTPUs are numbered from 1");
    if (o.rtpu != 0 && o.host_root) bad("%s", "--host-server runs in slot 0 only (--rtpu 0)");
    if (o.allow_shell && !o.host_root) bad("%s", "--host-allow-shell is an option of --host-server");
    if (o.host_root && !o.name) o.name = "host-server";  // how status and the table show slot 0
    // Programs: PATH [ARG...], separated by "--".
    while (i < argc) {
        if (!std::strcmp(argv[i], "--")) {
            ++i;
            continue;
        }
        Program p;
        p.path = argv[i];
        p.args.push_back(argv[i]);
        for (++i; i < argc && std::strcmp(argv[i], "--"); ++i) p.args.push_back(argv[i]);
        o.programs.push_back(std::move(p));
    }
    if (o.programs.size() > CHM_PROGRAM_MAX) bad("more than %s programs", "32");
    for (const Program& p : o.programs) {
        struct stat st;
        if (::stat(p.path.c_str(), &st) != 0) {
            std::fprintf(stderr, "chimera-rtpu: program %s: %s\n", p.path.c_str(), std::strerror(errno));
            std::exit(1);
        }
        if (!S_ISREG(st.st_mode)) {
            std::fprintf(stderr, "chimera-rtpu: program %s: not a regular file\n", p.path.c_str());
            std::exit(1);
        }
    }
    return o;
}

// ------------------------------------------------------------ shutdown

int g_sigfd = -1;
int g_signo = 0;
chm_sem_t g_stop;

// Interrupt context: consume what made the line ready, wake the task.
void on_signal_line(int, void*) {
    signalfd_siginfo si;
    bool any = false;
    while (::read(g_sigfd, &si, sizeof si) == ssize_t(sizeof si)) {
        if (!g_signo) g_signo = int(si.ssi_signo);
        any = true;
    }
    if (any) (void)chm_sem_v(&g_stop);
}

void shutdown_task(void*) {
    while (chm_sem_p(&g_stop) != 0) {
    }
    chm_kernel_stop(0);
}

int setup_shutdown() {
    sigset_t set;
    sigemptyset(&set);
    sigaddset(&set, SIGTERM);
    sigaddset(&set, SIGINT);
    sigaddset(&set, SIGHUP);
    g_sigfd = ::signalfd(-1, &set, SFD_NONBLOCK | SFD_CLOEXEC);
    if (g_sigfd < 0) return -errno;
    if (int e = chm_sem_init(&g_stop, CHM_SEM_COUNTING, 0, 0)) return e;  // a wake-up, owned by nobody
    if (int e = chm_irq_install(kSignalLine, on_signal_line, nullptr)) return e;
    if (int e = chm_irq_attach_fd(kSignalLine, g_sigfd, POLLIN)) return e;
    chm_task_attr_t attr;
    chm_task_attr_init(&attr);
    attr.name = "shutdown";
    attr.priority = kShutdownPriority;
    chm_tid_t tid;
    return chm_task_spawn(&tid, shutdown_task, nullptr, &attr);
}

const char* policy_name(chm_sched_policy p) {
    switch (p) {
    case CHM_SCHED_MUF: return "MUF";
    case CHM_SCHED_RM: return "RM";
    case CHM_SCHED_EDF: return "EDF";
    case CHM_SCHED_MLF: return "MLF";
    case CHM_SCHED_FIXED: return "FIXED";
    default: return "user";
    }
}

}  // namespace

int main(int argc, char** argv) {
    const Options o = parse(argc, argv);
    std::setvbuf(stdout, nullptr, _IOLBF, 0);  // logs are read while it runs

    // Block the stop signals before any thread exists (the backplane's
    // monitor, the kernel's timer): they are read from the signalfd only.
    // Block the kernel's timer signal too until the kernel installs its
    // handler (chm_kernel_init unblocks it): from the join on, the table
    // names this thread, and a peer's mailbox ring before the kernel is up
    // would be that signal's default action, death.
    sigset_t set;
    sigemptyset(&set);
    sigaddset(&set, SIGTERM);
    sigaddset(&set, SIGINT);
    sigaddset(&set, SIGHUP);
    sigaddset(&set, chm::port::timer_signal());
    pthread_sigmask(SIG_BLOCK, &set, nullptr);

    char path[4096];
    if (o.backplane) {
        std::snprintf(path, sizeof path, "%s", o.backplane);
    } else if (chm_bp_default_path(path, sizeof path) != 0) {
        std::fprintf(stderr, "chimera-rtpu: default backplane path too long\n");
        return 1;
    }
    for (const char* d : o.program_dirs)
        if (int r = chm_program_trust_dir(d)) {
            std::fprintf(stderr, "chimera-rtpu: --programs %s: %s\n", d, std::strerror(-r));
            return 1;
        }
    if (const std::string why = chimera_rtpu::apply(o.realtime); !why.empty()) {
        std::fprintf(stderr, "chimera-rtpu: RTPU %d: %s\n", o.rtpu, why.c_str());
        return 1;
    }
    auto cannot_join = [&](int r) {
        const char* why = chm_bp_last_error();
        if (std::strstr(why, std::strerror(-r)))
            std::fprintf(stderr, "chimera-rtpu: cannot join as RTPU %d: %s\n", o.rtpu, why);
        else
            std::fprintf(stderr, "chimera-rtpu: cannot join as RTPU %d: %s (%s)\n", o.rtpu, why, std::strerror(-r));
        return 1;
    };
    // Whether the file may be attached, while root can still open any file
    // to say why not (owner, mode, fix) rather than "permission denied".
    if (int r = chm_bp_check_file(path); r != 0 && r != -ENOENT) return cannot_join(r);
    // Set up: nothing below needs a capability (SECURITY.md, least privilege).
    if (const std::string why = chimera_rtpu::drop_privileges(o.realtime); !why.empty()) {
        std::fprintf(stderr, "chimera-rtpu: RTPU %d: %s\n", o.rtpu, why.c_str());
        return 1;
    }
    if (int r = chm_bp_join(path, o.rtpu, o.name)) return cannot_join(r);
    chm_kernel_config_t cfg;
    chm_kernel_config_init(&cfg);
    cfg.policy = o.policy;
    cfg.rtpu_id = o.rtpu;
    cfg.idle_poll_ns = std::uint64_t(o.idle_poll_us) * 1000u;
    cfg.timer_lead_ns = o.timer_lead_us < 0 ? CHM_TIMER_LEAD_AUTO : std::int64_t(o.timer_lead_us) * 1000;
    auto fail = [&](const char* what, int r) {
        std::fprintf(stderr, "chimera-rtpu: RTPU %d: %s: %s\n", o.rtpu, what, std::strerror(-r));
        chm::host::console::stop();
        chm::host::server::stop();
        chm::xmail::server_stop();
        chm::ipc::wake_unbind_kernel();
        chm_kernel_fini();
        (void)chm_bp_leave();
        return 1;
    };
    if (int r = chm_kernel_init(&cfg)) {
        std::fprintf(stderr, "chimera-rtpu: RTPU %d: cannot start the kernel: %s\n", o.rtpu, std::strerror(-r));
        (void)chm_bp_leave();
        return 1;
    }
    chm_err_rtpu_set(o.rtpu);
    if (int r = chm::ipc::wake_bind_kernel()) return fail("cannot bind the mailbox to the backplane", r);
    if (int r = chm::xmail::server_start(kServerPriority)) {
        if (r != -EMSGSIZE) return fail("cannot start the express-mail server", r);
        std::fprintf(stderr, "chimera-rtpu: RTPU %d: warning: the backplane's ring records are below %d bytes: "
                     "no express mail\n", o.rtpu, CHM_RTPU_RECORD_MIN);
    }
    const std::string console_socket = std::string(path) + ".console";
    if (o.host_root) {
        chm::host::server::Options ho;
        ho.root = o.host_root;
        ho.allow_shell = o.allow_shell;
        ho.console_socket = console_socket.c_str();
        if (int r = chm::host::server::start(ho)) return fail("cannot start the host server", r);
    }
    if (int r = setup_shutdown()) return fail("cannot set up the stop signals", r);
    // Tasks' stdio through the host server to the console (to the log when
    // no host server answers); the host server's own goes to its log.
    if (!o.host_root && o.console_stdio) {
        if (int r = chm::host::console::start(kStdioPriority, o.drop_orphans)) {
            if (r != -EMSGSIZE) return fail("cannot route stdio to the console", r);
            std::fprintf(stderr, "chimera-rtpu: RTPU %d: warning: ring records too small for a line: tasks' "
                         "stdio stays in this log\n", o.rtpu);
        }
    }

    for (const Program& p : o.programs) {
        std::vector<const char*> args;
        for (const std::string& a : p.args) args.push_back(a.c_str());
        const int r = chm_program_load(p.path.c_str(), int(args.size()), args.data(), nullptr, nullptr);
        if (r < 0) {
            const char* why = chm_program_error();
            if (*why) std::fprintf(stderr, "chimera-rtpu: RTPU %d: cannot load %s\n", o.rtpu, why);
            else std::fprintf(stderr, "chimera-rtpu: RTPU %d: cannot load %s: %s\n", o.rtpu, p.path.c_str(),
                              std::strerror(-r));
            chm::host::console::stop();
            chm::host::server::stop();
            chm::xmail::server_stop();
            chm::ipc::wake_unbind_kernel();
            chm_kernel_fini();
            (void)chm_bp_leave();
            return 1;
        }
    }
    std::string host;  // what was asked of the host OS, for the log
    if (o.realtime.fifo_priority) host += ", SCHED_FIFO " + std::to_string(o.realtime.fifo_priority);
    if (o.realtime.cpu >= 0) host += ", CPU " + std::to_string(o.realtime.cpu);
    if (o.realtime.lock_memory) host += ", memory locked";
    if (o.idle_poll_us) host += ", idle poll " + std::to_string(o.idle_poll_us) + " us";
    if (o.timer_lead_us >= 0) host += ", timer lead " + std::to_string(o.timer_lead_us) + " us";
    if (o.host_root)
        host += std::string(", host server for ") + chm::host::server::fs_root() + (o.allow_shell ? " (shells allowed)" : "");
    std::printf("chimera-rtpu: RTPU %d joined %s (pid %d, %s%s, %zu program%s)\n", o.rtpu, path, int(::getpid()),
                policy_name(o.policy), host.c_str(), o.programs.size(), o.programs.size() == 1 ? "" : "s");
    std::fflush(stdout);

    const int code = chm_kernel_run();

    chm::host::console::stop();
    chm::host::server::stop();
    chm::xmail::server_stop();
    chm::ipc::wake_unbind_kernel();
    chm_kernel_fini();
    (void)chm_bp_leave();
    if (g_signo)
        std::printf("chimera-rtpu: RTPU %d stopped by %s, left the backplane\n", o.rtpu, strsignal(g_signo));
    else
        std::printf("chimera-rtpu: RTPU %d stopped (code %d), left the backplane\n", o.rtpu, code);
    std::fflush(stdout);
    if (g_signo) return 0;
    return code < 0 ? 1 : code & 0xFF;
}
