// The command interpreter (chimera/cmdi.h): interpreters, commands and
// their errors, finding a command by name or prefix, suggestions, running
// a line, the shell escape.
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdarg>
#include <cstring>

#include "chimera/err.h"
#include "cmdi.hpp"

extern char** environ;

namespace chm::cmdi {

int fail(chm_cmdi* c, int status, const std::string& msg) noexcept {
    if (c) {
        try {
            c->error = msg;
        } catch (...) {
            c->error.clear();  // out of memory: no text rather than none at all
        }
        c->error_set = true;
    }
    chm_err_set_last("%s", msg.c_str());  // chm_err_last
    return status;
}

int failf(chm_cmdi* c, int status, const char* fmt, ...) noexcept {
    char buf[1024];
    va_list ap;
    va_start(ap, fmt);
    std::vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    return fail(c, status, buf);
}

FILE* out(const chm_cmdi* c) { return c->out ? c->out : stdout; }

std::string check_name(const char* name, bool is_command) {
    const char* what = is_command ? "command name" : "interpreter name";
    if (!name) return std::string(what) + " is NULL";
    const std::size_t len = std::strlen(name);
    if (len == 0) return std::string(what) + " is empty";
    if (len > CHM_CMDI_NAME_MAX)
        return std::string(what) + " '" + printable(name) + "' is longer than " +
               std::to_string(CHM_CMDI_NAME_MAX) + " bytes";
    for (std::size_t i = 0; i < len; ++i) {
        const char ch = name[i];
        const bool ok = (ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') || (ch >= '0' && ch <= '9') ||
                        ch == '_' || ch == '-' || ch == '.';
        if (!ok)
            return std::string(what) + " '" + printable(name) + "' has the character '" +
                   printable(std::string_view(&name[i], 1)) + "' at byte " + std::to_string(i + 1) +
                   " (allowed: letters, digits, '_', '-', '.')";
    }
    if (is_command && (name[0] == '-' || name[0] == '.'))
        return std::string(what) + " '" + name + "' starts with '" + name[0] + "'";
    return "";
}

std::size_t distance(std::string_view a, std::string_view b) {
    auto low = [](char ch) { return (ch >= 'A' && ch <= 'Z') ? char(ch - 'A' + 'a') : ch; };
    const std::size_t n = a.size(), m = b.size();
    // Three rows of the (n+1) x (m+1) table: i-2, i-1, i.
    std::vector<std::size_t> r2(m + 1), r1(m + 1), r0(m + 1);
    for (std::size_t j = 0; j <= m; ++j) r1[j] = j;
    for (std::size_t i = 1; i <= n; ++i) {
        r0[0] = i;
        for (std::size_t j = 1; j <= m; ++j) {
            const std::size_t cost = low(a[i - 1]) == low(b[j - 1]) ? 0 : 1;
            std::size_t d = std::min({r1[j] + 1, r0[j - 1] + 1, r1[j - 1] + cost});
            if (i > 1 && j > 1 && low(a[i - 1]) == low(b[j - 2]) && low(a[i - 2]) == low(b[j - 1]))
                d = std::min(d, r2[j - 2] + 1);
            r0[j] = d;
        }
        std::swap(r2, r1);
        std::swap(r1, r0);
    }
    return r1[m];
}

std::string resolve(const chm_cmdi* c, const std::string& word) {
    if (c->commands.count(word)) return word;
    auto p = c->commands.lower_bound(word);
    if (p == c->commands.end() || p->first.compare(0, word.size(), word) != 0) return "";
    const auto q = std::next(p);
    if (q != c->commands.end() && q->first.compare(0, word.size(), word) == 0) return "";
    return p->first;
}

namespace {

// The closest command name to `word` within the bound of cmdi.h; "" if none.
std::string closest(const chm_cmdi* c, std::string_view word) {
    const std::size_t bound = word.size() <= 4 ? 1 : word.size() <= 8 ? 2 : 3;
    auto len_diff = [&](const std::string& n) {
        return n.size() > word.size() ? n.size() - word.size() : word.size() - n.size();
    };
    std::string best;
    std::size_t best_d = bound + 1;
    for (const auto& [name, cmd] : c->commands) {  // alphabetical: full ties keep the first
        if (len_diff(name) > bound) continue;
        const std::size_t d = distance(word, name);
        if (d >= word.size()) continue;
        if (d < best_d || (d == best_d && len_diff(name) < len_diff(best))) {
            best = name;
            best_d = d;
        }
    }
    return best;
}

// Restores c->depth however the call ends.
struct DepthGuard {
    chm_cmdi* c;
    explicit DepthGuard(chm_cmdi* cc) : c(cc) { ++c->depth; }
    ~DepthGuard() { --c->depth; }
};

// "!cmd": /bin/sh -c cmd, its stdout and stderr on c's output stream.
int shell(chm_cmdi* c, std::string_view cmd) {
    if (cmd.empty()) return fail(c, -EINVAL, "shell escape: no command after '!'");
    if (!c->allow_shell)
        return fail(c, -EPERM,
                    "shell escape refused: " + c->name + " does not allow shell commands ('!" +
                        printable(cmd) + "')");
    std::fflush(out(c));
    std::fflush(stdout);
    std::fflush(stderr);
    posix_spawn_file_actions_t fa;
    posix_spawnattr_t attr;
    posix_spawn_file_actions_init(&fa);
    posix_spawnattr_init(&attr);
    const int fd = fileno(out(c));
    if (fd >= 0 && fd != STDOUT_FILENO) {
        posix_spawn_file_actions_adddup2(&fa, fd, STDOUT_FILENO);
        posix_spawn_file_actions_adddup2(&fa, fd, STDERR_FILENO);
    }
    // As system(3): the shell gets default SIGINT/SIGQUIT and no blocked
    // signals; this process ignores them while it waits.
    sigset_t def, none;
    sigemptyset(&def);
    sigaddset(&def, SIGINT);
    sigaddset(&def, SIGQUIT);
    sigemptyset(&none);
    posix_spawnattr_setsigdefault(&attr, &def);
    posix_spawnattr_setsigmask(&attr, &none);
    posix_spawnattr_setflags(&attr, POSIX_SPAWN_SETSIGDEF | POSIX_SPAWN_SETSIGMASK);
    struct sigaction ign {}, old_int {}, old_quit {};
    ign.sa_handler = SIG_IGN;
    sigemptyset(&ign.sa_mask);
    sigaction(SIGINT, &ign, &old_int);
    sigaction(SIGQUIT, &ign, &old_quit);
    std::string cmdline(cmd);
    char* argv[] = {const_cast<char*>("sh"), const_cast<char*>("-c"), cmdline.data(), nullptr};
    pid_t pid = -1;
    const int err = posix_spawn(&pid, "/bin/sh", &fa, &attr, argv, environ);
    posix_spawn_file_actions_destroy(&fa);
    posix_spawnattr_destroy(&attr);
    int status = 0;
    int rc = 0;
    if (err == 0) {
        while (waitpid(pid, &status, 0) < 0) {
            if (errno != EINTR) {
                rc = -errno;
                break;
            }
        }
    }
    sigaction(SIGINT, &old_int, nullptr);
    sigaction(SIGQUIT, &old_quit, nullptr);
    if (err) return failf(c, -err, "shell escape: cannot start /bin/sh: %s", std::strerror(err));
    if (rc) return failf(c, rc, "shell escape: waiting for /bin/sh: %s", std::strerror(-rc));
    const std::string shown = printable(cmd);
    if (WIFSIGNALED(status))
        return failf(c, 128 + WTERMSIG(status), "!%s: killed by signal %d (%s)", shown.c_str(),
                     WTERMSIG(status), strsignal(WTERMSIG(status)));
    const int code = WIFEXITED(status) ? WEXITSTATUS(status) : 255;
    if (code) return failf(c, code, "!%s: exit status %d", shown.c_str(), code);
    return 0;
}

int run_words(chm_cmdi* c, std::vector<std::string>& words) {
    const std::string& word = words[0];
    auto it = c->commands.find(word);
    if (it == c->commands.end()) {
        std::vector<std::string> hits;
        for (auto p = c->commands.lower_bound(word);
             p != c->commands.end() && p->first.compare(0, word.size(), word) == 0; ++p)
            hits.push_back(p->first);
        if (hits.empty()) {
            const std::string near = closest(c, word);
            return fail(c, -ENOENT,
                        "unknown command '" + printable(word) + "'" +
                            (near.empty() ? "; 'help' lists the commands" : "; did you mean '" + near + "'?"));
        }
        if (hits.size() > 1) {
            std::string list;
            for (std::size_t i = 0; i < hits.size() && i < 8; ++i) list += (i ? ", " : "") + hits[i];
            if (hits.size() > 8) list += ", ... (" + std::to_string(hits.size()) + " in all)";
            return fail(c, -ENOTUNIQ, "ambiguous command '" + printable(word) + "': " + list);
        }
        it = c->commands.find(hits[0]);
    }
    const std::string name = it->first;
    const chm_cmdi_fn fn = it->second.fn;
    void* user = it->second.user;
    words[0] = name;
    std::vector<char*> argv;
    for (std::string& w : words) argv.push_back(w.data());
    argv.push_back(nullptr);
    c->error_set = false;
    const int rc = fn(c, static_cast<int>(words.size()), argv.data(), user);
    if (rc != 0 && !c->error_set) {
        if (rc < 0 && rc > -4096)
            return failf(c, rc, "%s failed: %s (status %d)", name.c_str(), std::strerror(-rc), rc);
        return failf(c, rc, "%s failed with status %d", name.c_str(), rc);
    }
    return rc;
}

}  // namespace

}  // namespace chm::cmdi

using namespace chm::cmdi;

extern "C" {

chm_cmdi_t* chm_cmdi_create(const char* name) {
    if (!check_name(name, false).empty()) {
        errno = EINVAL;
        return nullptr;
    }
    chm_cmdi* c = new (std::nothrow) chm_cmdi;
    if (!c) {
        errno = ENOMEM;
        return nullptr;
    }
    if (guarded(c, [&] {
            c->name = name;
            add_builtins(c);
            return 0;
        })) {
        delete c;
        errno = ENOMEM;
        return nullptr;
    }
    return c;
}

const char* chm_cmdi_last_error(const chm_cmdi_t* c) { return c ? c->error.c_str() : ""; }

int chm_cmdi_error(chm_cmdi_t* c, int status, const char* fmt, ...) {
    if (!c || !fmt) return fail(c, -EINVAL, "chm_cmdi_error: NULL argument");
    char buf[1024];
    va_list ap;
    va_start(ap, fmt);
    std::vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    return fail(c, status, buf);
}

int chm_cmdi_add(chm_cmdi_t* c, const char* name, chm_cmdi_fn fn, void* user, const char* usage,
                 const char* help) {
    if (!c) return -EINVAL;
    return guarded(c, [&] {
        const std::string bad = check_name(name, true);
        if (!bad.empty()) return fail(c, -EINVAL, "chm_cmdi_add: " + bad);
        if (!fn) return fail(c, -EINVAL, std::string("chm_cmdi_add: command '") + name + "' has a NULL function");
        if (c->commands.count(name))
            return fail(c, -EEXIST, std::string("chm_cmdi_add: a command '") + name + "' exists already");
        c->commands[name] = Command{fn, user, usage ? usage : "", help ? help : ""};
        return 0;
    });
}

int chm_cmdi_set_output(chm_cmdi_t* c, FILE* stream) {
    if (!c) return -EINVAL;
    c->out = stream;
    return 0;
}

int chm_cmdi_printf(chm_cmdi_t* c, const char* fmt, ...) {
    if (!c || !fmt) return fail(c, -EINVAL, "chm_cmdi_printf: NULL argument");
    va_list ap;
    va_start(ap, fmt);
    const int n = std::vfprintf(out(c), fmt, ap);
    va_end(ap);
    if (n < 0) return fail(c, -EIO, "chm_cmdi_printf: writing the output stream failed");
    return n;
}

int chm_cmdi_allow_shell(chm_cmdi_t* c, int on) {
    if (!c) return -EINVAL;
    if (on != 0 && on != 1) return failf(c, -EINVAL, "chm_cmdi_allow_shell: on must be 0 or 1, not %d", on);
    c->allow_shell = on;
    return 0;
}

int chm_cmdi_keep_going(chm_cmdi_t* c, int on) {
    if (!c) return -EINVAL;
    if (on != 0 && on != 1) return failf(c, -EINVAL, "chm_cmdi_keep_going: on must be 0 or 1, not %d", on);
    c->keep_going = on;
    return 0;
}

int chm_cmdi_suggest(chm_cmdi_t* c, const char* word, char* buf, size_t len) {
    if (!c) return -EINVAL;
    if (!word || !buf || len == 0) return fail(c, -EINVAL, "chm_cmdi_suggest: NULL argument or len 0");
    return guarded(c, [&] {
        const std::string near = closest(c, word);
        if (near.empty()) return fail(c, -ENOENT, "no command name is close to '" + printable(word) + "'");
        if (near.size() >= len)
            return failf(c, -ENAMETOOLONG, "suggestion '%s' does not fit in %zu bytes", near.c_str(), len);
        std::memcpy(buf, near.c_str(), near.size() + 1);
        return 0;
    });
}

int chm_cmdi_run_line(chm_cmdi_t* c, const char* line) {
    if (!c) return -EINVAL;
    if (!line) return fail(c, -EINVAL, "chm_cmdi_run_line: NULL line");
    return guarded(c, [&] {
        if (c->depth >= kMaxLineDepth)
            return failf(c, -ELOOP, "lines run by commands are nested %d deep (a command running itself?)",
                         kMaxLineDepth);
        if (c->depth == 0 && c->script_depth == 0) c->quit = false;
        DepthGuard guard(c);
        std::string_view rest(line);
        const std::size_t first = rest.find_first_not_of(" \t\r\n\v\f");
        if (first != std::string_view::npos && rest[first] == '!') {
            rest.remove_prefix(first + 1);
            const std::size_t b = rest.find_first_not_of(" \t\r\n\v\f");
            rest.remove_prefix(b == std::string_view::npos ? rest.size() : b);
            const std::size_t e = rest.find_last_not_of(" \t\r\n\v\f");
            rest = rest.substr(0, e == std::string_view::npos ? 0 : e + 1);
            return shell(c, rest);
        }
        std::vector<std::string> words;
        std::string err;
        if (split(line, words, err)) return fail(c, -EINVAL, err);
        if (words.empty()) return 0;
        return run_words(c, words);
    });
}

int chm_cmdi_quit(chm_cmdi_t* c) {
    if (!c) return -EINVAL;
    c->quit = true;
    return 0;
}

}  // extern "C"
