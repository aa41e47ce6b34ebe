// chm_host_run on the host: an argument vector run with posix_spawnp in
// the client's working directory, on the terminal of the console that owns
// the caller's RTPU (else the host server's own stdin, stdout and stderr),
// never through a shell unless the server was started allowing one; the
// worker waits for it to exit.
#include <cerrno>
#include <csignal>
#include <cstring>
#include <mutex>
#include <set>
#include <vector>

#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include "host/server/server.hpp"

extern char** environ;

namespace chm::host::server {

namespace {

std::mutex g_mu;
std::set<pid_t> g_running;

bool is_shell(const char* prog) {
    const char* base = std::strrchr(prog, '/');
    base = base ? base + 1 : prog;
    static const char* const shells[] = {"sh", "bash", "dash", "zsh", "ksh", "mksh", "csh", "tcsh", "fish", "busybox"};
    for (const char* s : shells)
        if (!std::strcmp(base, s)) return true;
    return false;
}

}  // namespace

int run_program(const Client& c, std::uint32_t slot, const char* text, std::uint32_t len, std::uint64_t argc,
                bool allow_shell, std::string* why) {
    if (argc < 1 || argc > 256 || len == 0 || text[len - 1] != 0) {
        *why = "malformed argument vector";
        return -EINVAL;
    }
    std::vector<char*> argv;
    for (const char* p = text; p < text + len && argv.size() < argc; p += std::strlen(p) + 1)
        argv.push_back(const_cast<char*>(p));
    if (argv.size() != argc || !*argv[0]) {
        *why = "malformed argument vector";
        return -EINVAL;
    }
    argv.push_back(nullptr);
    if (is_shell(argv[0]) && !allow_shell) {
        *why = std::string(argv[0]) + " is a shell, and this host server runs none (--host-allow-shell)";
        return -EPERM;
    }
    const std::string dir = c.cwd.empty() ? fs_root() : fs_root() + "/" + c.cwd;

    posix_spawn_file_actions_t fa;
    posix_spawnattr_t at;
    posix_spawn_file_actions_init(&fa);
    posix_spawnattr_init(&at);
    posix_spawn_file_actions_addchdir_np(&fa, dir.c_str());
    int term[3];
    const bool on_console = console_terminal(slot, term) == 0;
    if (on_console)
        for (int j = 0; j < 3; ++j) posix_spawn_file_actions_adddup2(&fa, term[j], j);
    // The kernel thread's signal handlers and the workers' full mask must
    // not pass to the program.
    sigset_t none, all;
    sigemptyset(&none);
    sigfillset(&all);
    posix_spawnattr_setsigmask(&at, &none);
    posix_spawnattr_setsigdefault(&at, &all);
    posix_spawnattr_setflags(&at, POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF);
    pid_t pid = -1;
    const int e = posix_spawnp(&pid, argv[0], &fa, &at, argv.data(), environ);
    posix_spawn_file_actions_destroy(&fa);
    posix_spawnattr_destroy(&at);
    if (on_console)
        for (int t : term) ::close(t);
    struct Back {  // the console gets its terminal back on every path
        bool on;
        std::uint32_t slot;
        ~Back() {
            if (on) console_terminal_back(slot);
        }
    } back{on_console, slot};
    if (e != 0) {
        *why = std::string("cannot run ") + argv[0] + ": " + std::strerror(e);
        return -e;
    }
    {
        std::lock_guard<std::mutex> l(g_mu);
        g_running.insert(pid);
    }
    int st = 0;
    pid_t r;
    do r = ::waitpid(pid, &st, 0);
    while (r < 0 && errno == EINTR);
    {
        std::lock_guard<std::mutex> l(g_mu);
        g_running.erase(pid);
    }
    if (r < 0) {
        *why = std::string("lost ") + argv[0] + ": " + std::strerror(errno);
        return -ECHILD;
    }
    return WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
}

void run_stop_all() {
    std::lock_guard<std::mutex> l(g_mu);
    for (pid_t p : g_running) ::kill(p, SIGTERM);
}

}  // namespace chm::host::server
