// `chimera console`: one terminal for the RTPUs it owns (docs/architecture.md,
// "Console"). It connects to the host server's console socket
// (<backplane>.console), takes the RTPUs asked for (default: every one no
// other console owns), prints their tasks' output lines prefixed "[N] ", and
// runs commands through the command-interpreter library (chimera/cmdi.h):
// load, tasks, kill, stop, fg, rtpus, and cmdi's own help, source, history,
// quit. One RTPU owns stdin at a time (`fg N`; the lowest owned at first):
// when one of its tasks reads stdin, the next line typed goes to that task;
// a task on another RTPU that reads stdin waits, and the console says
// "Waiting for TTY Input" until the user gives its RTPU the terminal.
// The terminal itself is lent to the host server (SCM_RIGHTS): a host
// program a task runs (chm_host_run) runs on it, the console keeping off
// stdin until it ends.
#include <cerrno>
#include <climits>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include "chimera/bp.h"
#include "chimera/cmdi.h"
#include "chimera/rtpu.h"
#include "cmd.hpp"
#include "host/hostio.hpp"
#include "../parse_num.hpp"

namespace chimera_cmd {

namespace {

using chm::host::Entry;
using chm::host::Frame;
using chm::host::recv_all;

struct Console {
    int sock = -1;
    std::uint32_t owned = 0;
    int fg = -1;                          // the RTPU that owns stdin
    std::int64_t wants[CHM_BP_MAX_SLOTS]; // task reading stdin, per RTPU (-1: none)
    chm_cmdi_t* cmdi = nullptr;
    bool interactive = false;             // a cmdi session is on the terminal
    bool feeding = false;                 // the next line typed goes to RTPU fg
    std::string typed;                    // a task's input line, so far
    bool over = false;
    bool lent = false;                    // a host program runs on this terminal
};
Console g;

bool write_all(int fd, const void* p, std::size_t n) {
    const char* s = static_cast<const char*>(p);
    while (n) {
        const ssize_t w = ::send(fd, s, n, MSG_NOSIGNAL);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) return false;
        s += w;
        n -= std::size_t(w);
    }
    return true;
}


bool send_frame(std::uint32_t type, std::uint32_t rtpu, const void* data, std::uint32_t len) {
    const Frame f{type, rtpu, 0, len};
    return write_all(g.sock, &f, sizeof f) && (!len || write_all(g.sock, data, len));
}

// Text for the terminal: above the line being edited, or as it is.
void show(const std::string& text) {
    if (g.interactive) {
        (void)chm_cmdi_print_async(g.cmdi, text.c_str());
    } else {
        std::fputs(text.c_str(), stdout);
        if (text.empty() || text.back() != '\n') std::fputc('\n', stdout);
        std::fflush(stdout);
    }
}

void begin_commands() {
    if (g.interactive || g.over) return;
    g.interactive = chm_cmdi_interactive_begin(g.cmdi, "chimera> ") == 0;
}

// The fg RTPU has a reader: the terminal goes to it for one line.
void maybe_feed() {
    if (g.feeding || g.fg < 0 || g.wants[g.fg] < 0) return;
    if (g.interactive) {
        (void)chm_cmdi_interactive_end(g.cmdi);
        g.interactive = false;
    }
    g.feeding = true;
    g.typed.clear();
    std::printf("[%d] input (:COMMAND for the console)> ", g.fg);  // the task's input line
    std::fflush(stdout);
}

void end_feed() {
    g.feeding = false;
    g.wants[g.fg] = -1;
    begin_commands();
}

// A frame from the host server. False: the connection is gone.
bool on_server() {
    Frame f;
    if (!recv_all(g.sock, &f, sizeof f) || f.len > chm::host::kFrameMax) return false;
    std::vector<char> data(f.len);
    if (f.len && !recv_all(g.sock, data.data(), f.len)) return false;
    if (f.rtpu >= CHM_BP_MAX_SLOTS) return true;
    if (f.type == chm::host::kFrameOut) {
        std::string text;
        for (std::uint32_t off = 0; off + sizeof(Entry) <= f.len;) {
            Entry e;
            std::memcpy(&e, data.data() + off, sizeof e);
            if (e.len > f.len - off - sizeof e) break;
            text += "[" + std::to_string(f.rtpu) + "] " + std::string(data.data() + off + sizeof e, e.len);
            if (text.back() != '\n') text += '\n';
            off += sizeof e + e.len;
        }
        if (!text.empty()) {
            text.pop_back();
            show(text);
        }
    } else if (f.type == chm::host::kFrameWant) {
        g.wants[f.rtpu] = f.tid;
        if (int(f.rtpu) == g.fg)
            maybe_feed();
        else
            show("[" + std::to_string(f.rtpu) + "] task " + std::to_string(f.tid) +
                 ": Waiting for TTY Input (fg " + std::to_string(f.rtpu) + " gives it the terminal)");
    } else if (f.type == chm::host::kFrameRun) {
        // A task's chm_host_run: the program has the terminal until it ends.
        g.lent = f.tid != 0;
        if (g.lent && g.interactive) {
            (void)chm_cmdi_interactive_end(g.cmdi);
            g.interactive = false;
        } else if (!g.lent && !g.feeding) {
            begin_commands();
            maybe_feed();
        }
    } else if (f.type == chm::host::kFrameOwned && f.len >= 4) {
        std::memcpy(&g.owned, data.data(), 4);
    }
    return true;
}

// Typed text while a task of RTPU fg reads: one line goes to it.
void on_feed_input() {
    char buf[1024];
    const ssize_t r = ::read(0, buf, sizeof buf);
    if (r <= 0) {  // end of input: the task reads end of file
        send_frame(chm::host::kFrameInput, std::uint32_t(g.fg), nullptr, 0);
        g.over = true;
        end_feed();
        return;
    }
    g.typed.append(buf, std::size_t(r));
    const std::size_t nl = g.typed.find('\n');
    if (nl == std::string::npos) return;
    if (g.typed[0] == ':') {  // a console command while a task has the terminal
        const int fg = g.fg;
        std::string line = g.typed.substr(1, nl - 1);
        if (!line.empty() && line.back() == '\r') line.pop_back();
        if (line == "quit" || line == "exit")
            g.over = true;
        else if (chm_cmdi_run_line(g.cmdi, line.c_str()) != 0)
            std::printf("%s\n", chm_cmdi_last_error(g.cmdi));
        g.feeding = false;
        if (g.fg != fg || g.over) {
            begin_commands();  // the terminal moved (fg) or the console ends
            maybe_feed();
        } else {
            maybe_feed();
        }
        return;
    }
    send_frame(chm::host::kFrameInput, std::uint32_t(g.fg), g.typed.data(), std::uint32_t(nl + 1));
    end_feed();
}

// Lend the host server this terminal for the programs tasks run
// (chm_host_run): stdin, stdout and stderr as SCM_RIGHTS.
bool send_terminal() {
    Frame f{chm::host::kFrameTerminal, 0, 0, 0};
    iovec io{&f, sizeof f};
    alignas(cmsghdr) char ctl[CMSG_SPACE(3 * sizeof(int))] = {};
    msghdr m{};
    m.msg_iov = &io;
    m.msg_iovlen = 1;
    m.msg_control = ctl;
    m.msg_controllen = sizeof ctl;
    cmsghdr* h = CMSG_FIRSTHDR(&m);
    h->cmsg_level = SOL_SOCKET;
    h->cmsg_type = SCM_RIGHTS;
    h->cmsg_len = CMSG_LEN(3 * sizeof(int));
    const int fds[3] = {0, 1, 2};
    std::memcpy(CMSG_DATA(h), fds, sizeof fds);
    return ::sendmsg(g.sock, &m, MSG_NOSIGNAL) == ssize_t(sizeof f);
}

// ------------------------------------------------------------ commands

int rtpu_arg(chm_cmdi_t* c, const char* s) {
    long n = 0;
    if (!chimera_tools::parse_num(s, 1, CHM_BP_MAX_SLOTS - 1, &n))
        return chm_cmdi_error(c, -EINVAL, "\"%s\" is not an RTPU number", s);
    return int(n);
}

int remote_error(chm_cmdi_t* c, int r) { return chm_cmdi_error(c, r, "%s", chm_rtpu_last_error()); }

int cmd_load(chm_cmdi_t* c, int argc, char** argv, void*) {
    if (argc < 3) return chm_cmdi_error(c, -EINVAL, "usage: load RTPU PROGRAM [ARG...]");
    const int n = rtpu_arg(c, argv[1]);
    if (n < 0) return n;
    char real[PATH_MAX];
    if (!realpath(argv[2], real)) return chm_cmdi_error(c, -errno, "%s: %s", argv[2], std::strerror(errno));
    std::vector<const char*> args = {real};
    for (int i = 3; i < argc; ++i) args.push_back(argv[i]);
    chm_tid_t tid;
    if (int r = chm_rtpu_spawn(n, real, int(args.size()), args.data(), &tid)) return remote_error(c, r);
    chm_cmdi_printf(c, "loaded %s on RTPU %d: task %lld\n", real, n, (long long)tid);
    return 0;
}

int cmd_tasks(chm_cmdi_t* c, int argc, char** argv, void*) {
    if (argc != 2) return chm_cmdi_error(c, -EINVAL, "usage: tasks RTPU");
    const int n = rtpu_arg(c, argv[1]);
    if (n < 0) return n;
    chm_rtpu_task_t t[64];
    int total = 0;
    const int k = chm_rtpu_tasks(n, t, 64, &total);
    if (k < 0) return remote_error(c, k);
    chm_cmdi_printf(c, "%8s  %-20s %-10s %12s %10s\n", "id", "name", "state", "cycles", "misses");
    for (int i = 0; i < k; ++i)
        chm_cmdi_printf(c, "%8lld  %-20s %-10s %12llu %10llu\n", (long long)t[i].id, t[i].name, task_state(t[i].state),
                        static_cast<unsigned long long>(t[i].cycles), static_cast<unsigned long long>(t[i].misses));
    return 0;
}

int cmd_kill(chm_cmdi_t* c, int argc, char** argv, void*) {
    if (argc != 3) return chm_cmdi_error(c, -EINVAL, "usage: kill RTPU TASK");
    const int n = rtpu_arg(c, argv[1]);
    if (n < 0) return n;
    long long id = 0;
    chm_tid_t tid;
    if (chimera_tools::parse_tid(argv[2], &id)) {
        tid = chm_tid_t(id);
    } else if (int r = chm_rtpu_find(n, argv[2], &tid)) {
        return remote_error(c, r);
    }
    if (int r = chm_rtpu_destroy(n, tid)) return remote_error(c, r);
    chm_cmdi_printf(c, "RTPU %d: task %lld destroyed\n", n, (long long)tid);
    return 0;
}

int cmd_stop(chm_cmdi_t* c, int argc, char** argv, void*) {
    if (argc != 2) return chm_cmdi_error(c, -EINVAL, "usage: stop RTPU");
    const int n = rtpu_arg(c, argv[1]);
    if (n < 0) return n;
    if (int r = chm_rtpu_stop(n, 0)) return remote_error(c, r);
    chm_cmdi_printf(c, "RTPU %d: stopping\n", n);
    return 0;
}

int cmd_fg(chm_cmdi_t* c, int argc, char** argv, void*) {
    if (argc != 2) return chm_cmdi_error(c, -EINVAL, "usage: fg RTPU");
    const int n = rtpu_arg(c, argv[1]);
    if (n < 0) return n;
    if (!(g.owned & (1u << n))) return chm_cmdi_error(c, -EPERM, "RTPU %d is not this console's (rtpus)", n);
    g.fg = n;
    chm_cmdi_printf(c, "RTPU %d has the terminal%s\n", n, g.wants[n] >= 0 ? " (a task is reading)" : "");
    return 0;
}


int cmd_rtpus(chm_cmdi_t* c, int, char**, void*) {
    chm_bp_status_t st;
    if (int r = chm_bp_status(&st)) return chm_cmdi_error(c, r, "%s", chm_bp_last_error());
    for (std::uint32_t s = 1; s < st.slots; ++s) {
        if (st.slot[s].state != CHM_BP_RUNNING || st.slot[s].kind != CHM_BP_KIND_RTPU) continue;
        chm_cmdi_printf(c, "RTPU %-2u %-16s pid %-7d %s%s%s\n", s, st.slot[s].name, int(st.slot[s].pid),
                        g.owned & (1u << s) ? "this console's" : "another console's or none",
                        int(s) == g.fg ? ", has the terminal" : "", g.wants[s] >= 0 ? ", a task reads stdin" : "");
    }
    return 0;
}

void add_commands(chm_cmdi_t* c) {
    (void)chm_cmdi_add(c, "load", cmd_load, nullptr, "RTPU PROGRAM [ARG...]",
                 "Load the control program PROGRAM on RTPU and start its main with the ARGs.");
    (void)chm_cmdi_add(c, "tasks", cmd_tasks, nullptr, "RTPU", "List the tasks of RTPU.");
    (void)chm_cmdi_add(c, "kill", cmd_kill, nullptr, "RTPU TASK", "Destroy task TASK (its id or name) of RTPU.");
    (void)chm_cmdi_add(c, "stop", cmd_stop, nullptr, "RTPU", "Stop RTPU (its shutdown hooks run).");
    (void)chm_cmdi_add(c, "fg", cmd_fg, nullptr, "RTPU",
                 "Give the terminal to RTPU: the next line typed while one of its tasks reads stdin goes to it.");
    (void)chm_cmdi_add(c, "rtpus", cmd_rtpus, nullptr, "", "The running RTPUs, which are this console's, who reads.");
}

}  // namespace

int cmd_console(const Options& o, const std::vector<const char*>& args) {
    std::uint32_t want = 0;
    const char* script = nullptr;
    for (std::size_t i = 0; i < args.size(); ++i) {
        const std::string a = args[i];
        if ((a == "--rtpus" || a == "--script") && i + 1 < args.size()) {
            const char* v = args[++i];
            if (a == "--script") {
                script = v;
                continue;
            }
            for (const char* p = v; *p;) {
                char* end = nullptr;
                const long n = std::strtol(p, &end, 10);
                if (end == p || n < 1 || n >= CHM_BP_MAX_SLOTS) {
                    say("--rtpus wants RTPU numbers like 1,2 (see chimera --help), not \"%s\"", v);
                    return 2;
                }
                want |= 1u << n;
                p = *end == ',' ? end + 1 : end;
                if (*end && *end != ',') {
                    say("--rtpus wants RTPU numbers like 1,2 (see chimera --help), not \"%s\"", v);
                    return 2;
                }
            }
        } else {
            say("console: unknown argument \"%s\" (see chimera --help)", a.c_str());
            return 2;
        }
    }
    if (attach(o) != 0) return 1;
    const std::string path = o.backplane + ".console";
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    if (path.size() >= sizeof addr.sun_path) {
        say("console socket path %s is too long", path.c_str());
        return 1;
    }
    std::memcpy(addr.sun_path, path.c_str(), path.size());
    g.sock = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (g.sock < 0 || ::connect(g.sock, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0) {
        say("cannot reach the host server at %s: %s (is the system started with its host server? chimera status)",
            path.c_str(), std::strerror(errno));
        return 1;
    }
    for (auto& w : g.wants) w = -1;
    if (!send_frame(chm::host::kFrameOwn, 0, &want, sizeof want)) {
        say("the host server closed the console socket");
        return 1;
    }
    if (isatty(0) && !send_terminal()) {
        say("the host server closed the console socket");
        return 1;
    }
    // The answer says which RTPUs this console got.
    for (g.owned = UINT32_MAX; g.owned == UINT32_MAX;)
        if (!on_server()) {
            say("the host server closed the console socket");
            return 1;
        }
    for (int s = 1; s < CHM_BP_MAX_SLOTS && g.fg < 0; ++s)
        if (g.owned & (1u << s)) g.fg = s;
    std::string mine;
    chm_bp_status_t st;
    if (chm_bp_status(&st) == 0) {
        for (std::uint32_t s = 1; s < st.slots; ++s)
            if ((g.owned & (1u << s)) && st.slot[s].state == CHM_BP_RUNNING && st.slot[s].kind == CHM_BP_KIND_RTPU)
                mine += (mine.empty() ? "" : ",") + std::to_string(s);
    }
    std::printf("chimera console: RTPUs %s%s (terminal: %d); help lists the commands\n",
                mine.empty() ? "none running" : mine.c_str(), want ? "" : " and any that start later", g.fg);
    std::fflush(stdout);

    g.cmdi = chm_cmdi_create("chimera");
    if (!g.cmdi) return 1;
    add_commands(g.cmdi);
    // History across sessions, as a shell keeps it (a missing file is an
    // empty history; one that cannot be read is said and ignored).
    if (const char* home = std::getenv("HOME"); home && *home && isatty(0)) {
        const std::string history = std::string(home) + "/.chimera_history";
        if (chm_cmdi_history_file(g.cmdi, history.c_str()) != 0)
            std::printf("chimera console: history %s: %s\n", history.c_str(), chm_cmdi_last_error(g.cmdi));
    }
    if (script && chm_cmdi_run_script(g.cmdi, script) != 0) std::printf("%s\n", chm_cmdi_last_error(g.cmdi));
    std::fflush(stdout);
    begin_commands();
    while (!g.over) {
        // While a host program has the terminal, its input is the program's.
        pollfd fds[2] = {{g.lent ? -1 : 0, POLLIN, 0}, {g.sock, POLLIN, 0}};
        if (::poll(fds, 2, -1) < 0) {
            if (errno == EINTR) continue;
            break;
        }
        if (fds[1].revents) {
            if (!on_server()) {
                show("chimera console: the host server went away");
                break;
            }
            continue;  // its output first, then what was typed
        }
        if (fds[0].revents) {
            if (g.feeding) {
                on_feed_input();
            } else if (g.interactive) {
                if (chm_cmdi_interactive_step(g.cmdi) != 0) g.over = true;
                if (!g.over) maybe_feed();
            } else {
                g.over = true;
            }
        }
    }
    if (g.interactive) (void)chm_cmdi_interactive_end(g.cmdi);
    chm_cmdi_destroy(g.cmdi);
    ::close(g.sock);
    (void)chm_bp_leave();
    return 0;
}

}  // namespace chimera_cmd
