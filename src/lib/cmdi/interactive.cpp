// Interactive sessions of the command interpreter (chimera/cmdi.h): the
// blocking loop and the event-driven interface, history and its file,
// destroy. On a terminal with libedit (CHM_CMDI_LIBEDIT) lines are edited
// through its readline-compatible callback interface, which reads one
// character per call, so the caller's poll loop can watch other
// descriptors between keys; otherwise plain lines are read with read(2).
#include <fcntl.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdlib>
#include <cstring>

#include "cmdi.hpp"

#ifdef CHM_CMDI_LIBEDIT
#include <editline/readline.h>
#endif

namespace chm::cmdi {

namespace {

// The interpreter whose session is running (libedit's state is global).
chm_cmdi* g_session = nullptr;

// Runs one line read in a session; its error, if any, is printed.
void session_line(chm_cmdi* c, const char* line) {
    // Into the history without trailing blanks (completion leaves one),
    // unless a backslash before them makes one part of the last word.
    std::string entry(line);
    const std::size_t last = entry.find_last_not_of(" \t");
    if (last != std::string::npos && entry[last] != '\\') entry.erase(last + 1);
    if (last != std::string::npos) {
        (void)chm_cmdi_history_add(c, entry.c_str());
#ifdef CHM_CMDI_LIBEDIT
        if (c->session.editing) add_history(entry.c_str());
#endif
    }
    if (chm_cmdi_run_line(c, line) != 0) std::fprintf(out(c), "%s: %s\n", c->name.c_str(), c->error.c_str());
    std::fflush(out(c));
    if (c->quit) c->session.done = true;
}

#ifdef CHM_CMDI_LIBEDIT

std::vector<std::string> g_matches;
std::size_t g_next = 0;

// Command names starting with `text`, one per call (libedit frees them).
char* command_names(const char* text, int state) {
    if (state == 0) {
        g_matches.clear();
        g_next = 0;
        const std::string prefix(text);
        for (auto p = g_session->commands.lower_bound(prefix);
             p != g_session->commands.end() && p->first.compare(0, prefix.size(), prefix) == 0; ++p)
            g_matches.push_back(p->first);
    }
    return g_next < g_matches.size() ? strdup(g_matches[g_next++].c_str()) : nullptr;
}

// Tab: command names in the first word and after "help"; file names
// elsewhere (libedit's default when this returns NULL).
char** complete(const char* text, int start, int) {
    if (!g_session) return nullptr;
    const std::string before(rl_line_buffer, static_cast<std::size_t>(start));
    std::vector<std::string> words;
    std::string err;
    if (split(before, words, err) != 0) return nullptr;
    const bool names = words.empty() || (words.size() == 1 && std::strchr(" \t", before.back()) &&
                                         resolve(g_session, words[0]) == "help");
    if (!names) return nullptr;
    rl_attempted_completion_over = 1;
    return rl_completion_matches(text, command_names);
}

void on_line(char* line) {
    chm_cmdi* c = g_session;
    if (!line) {
        std::fputs("\n", stdout);
        c->session.done = true;
        return;
    }
    c->session.line_read = true;
    session_line(c, line);
    std::free(line);
}

#endif

// The prompt again, for plain reading on a terminal.
void plain_prompt(chm_cmdi* c) {
    if (!c->session.editing && !c->session.done && isatty(STDIN_FILENO)) {
        std::fputs(c->session.prompt.c_str(), stdout);
        std::fflush(stdout);
    }
}

int plain_step(chm_cmdi* c) {
    char buf[4096];
    const ssize_t n = ::read(STDIN_FILENO, buf, sizeof buf);
    if (n < 0) {
        if (errno == EINTR || errno == EAGAIN) return 0;
        return failf(c, -EIO, "reading stdin: %s", std::strerror(errno));
    }
    if (n == 0) {
        if (!c->session.pending.empty()) {
            const std::string line = std::move(c->session.pending);
            c->session.pending.clear();
            session_line(c, line.c_str());
        }
        c->session.done = true;
        return 0;
    }
    c->session.pending.append(buf, static_cast<std::size_t>(n));
    std::size_t nl;
    while (!c->session.done && (nl = c->session.pending.find('\n')) != std::string::npos) {
        std::string line = c->session.pending.substr(0, nl);
        c->session.pending.erase(0, nl + 1);
        if (!line.empty() && line.back() == '\r') line.pop_back();
        if (line.find('\0') != std::string::npos) {
            std::fprintf(out(c), "%s: NUL byte in the line\n", c->name.c_str());
            continue;
        }
        session_line(c, line.c_str());
        plain_prompt(c);
    }
    return 0;
}

int no_session(chm_cmdi* c, const char* fn) {
    return failf(c, -EINVAL, "%s: %s has no interactive session", fn, c->name.c_str());
}

}  // namespace

}  // namespace chm::cmdi

using namespace chm::cmdi;

extern "C" {

void chm_cmdi_destroy(chm_cmdi_t* c) {
    if (!c) return;
    if (g_session == c) {
        c->history_path.clear();  // destroy does not save
        (void)chm_cmdi_interactive_end(c);
    }
    delete c;
}

int chm_cmdi_has_line_editing(void) {
#ifdef CHM_CMDI_LIBEDIT
    return 1;
#else
    return 0;
#endif
}

int chm_cmdi_history_add(chm_cmdi_t* c, const char* line) {
    if (!c) return -EINVAL;
    if (!line) return fail(c, -EINVAL, "chm_cmdi_history_add: NULL line");
    return guarded(c, [&] {
        if (std::strchr(line, '\n')) return fail(c, -EINVAL, "chm_cmdi_history_add: the line holds a newline");
        if (std::strspn(line, " \t\r\v\f") == std::strlen(line)) return 0;
        if (!c->history.empty() && c->history.back() == line) return 0;
        c->history.emplace_back(line);
        if (c->history.size() > CHM_CMDI_HISTORY_MAX) c->history.erase(c->history.begin());
        return 0;
    });
}

int chm_cmdi_history_file(chm_cmdi_t* c, const char* path) {
    if (!c) return -EINVAL;
    if (!path || !*path) return fail(c, -EINVAL, "chm_cmdi_history_file: NULL or empty path");
    return guarded(c, [&] {
        std::string data;
        struct stat st {};
        if (::stat(path, &st) == 0 || errno != ENOENT) {
            const int rc = read_file(c, path, kMaxScript, data);
            if (rc) return fail(c, rc, "history file: " + c->error);
        }
        std::size_t pos = 0;
        while (pos < data.size()) {
            std::size_t nl = data.find('\n', pos);
            if (nl == std::string::npos) nl = data.size();
            const std::string line = data.substr(pos, nl - pos);
            pos = nl + 1;
            if (line.find('\0') == std::string::npos) (void)chm_cmdi_history_add(c, line.c_str());
        }
        c->history_path = path;
        return 0;
    });
}

int chm_cmdi_history_save(chm_cmdi_t* c) {
    if (!c) return -EINVAL;
    return guarded(c, [&] {
        if (c->history_path.empty()) return fail(c, -ENOENT, "chm_cmdi_history_save: no history file set");
        const std::string tmp = c->history_path + ".tmp";
        const std::string shown = printable(c->history_path);
        const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
        if (fd < 0) return failf(c, -errno, "history file '%s': %s", shown.c_str(), std::strerror(errno));
        std::string data;
        for (const std::string& h : c->history) data += h + "\n";
        std::size_t done = 0;
        int rc = 0;
        while (done < data.size()) {
            const ssize_t n = ::write(fd, data.data() + done, data.size() - done);
            if (n < 0 && errno == EINTR) continue;
            if (n < 0) {
                rc = -errno;
                break;
            }
            done += static_cast<std::size_t>(n);
        }
        if (::close(fd) < 0 && rc == 0) rc = -errno;
        if (rc == 0 && ::rename(tmp.c_str(), c->history_path.c_str()) < 0) rc = -errno;
        if (rc) {
            ::unlink(tmp.c_str());
            return failf(c, rc, "history file '%s': %s", shown.c_str(), std::strerror(-rc));
        }
        return 0;
    });
}

int chm_cmdi_interactive_begin(chm_cmdi_t* c, const char* prompt) {
    if (!c) return -EINVAL;
    return guarded(c, [&] {
        if (g_session)
            return failf(c, -EBUSY, "an interactive session is running already (of %s)", g_session->name.c_str());
        c->session = Session{};
        c->session.prompt = prompt ? prompt : c->name + "> ";
        c->quit = false;
#ifdef CHM_CMDI_LIBEDIT
        c->session.editing = isatty(STDIN_FILENO) && isatty(STDOUT_FILENO);
#endif
        c->session.active = true;
        g_session = c;
#ifdef CHM_CMDI_LIBEDIT
        if (c->session.editing) {
            rl_readline_name = c->name.c_str();
            rl_instream = stdin;
            rl_outstream = stdout;
            rl_attempted_completion_function = complete;
            clear_history();
            for (const std::string& h : c->history) add_history(h.c_str());
            std::fflush(stdout);
            rl_callback_handler_install(c->session.prompt.c_str(), on_line);
            return 0;
        }
#endif
        plain_prompt(c);
        return 0;
    });
}

int chm_cmdi_interactive_step(chm_cmdi_t* c) {
    if (!c) return -EINVAL;
    if (g_session != c) return no_session(c, "chm_cmdi_interactive_step");
    return guarded(c, [&] {
        // chm_cmdi_quit between lines ends the session too, without a read.
        if (c->quit) c->session.done = true;
        if (c->session.done) return 1;
#ifdef CHM_CMDI_LIBEDIT
        if (c->session.editing) {
            // A hung-up terminal reads as end of input; libedit would
            // return nothing and never call on_line.
            pollfd p{STDIN_FILENO, POLLIN, 0};
            if (::poll(&p, 1, 0) > 0 && (p.revents & (POLLHUP | POLLERR | POLLNVAL))) {
                c->session.done = true;
                return 1;
            }
            c->session.line_read = false;
            rl_callback_read_char();
            // libedit leaves its character-at-a-time mode to call on_line
            // (the command runs on a cooked terminal) and, in the version
            // of Debian 12, does not go back to it: installing the handler
            // again does, and shows the prompt for the next line.
            if (c->session.line_read && !c->session.done)
                rl_callback_handler_install(c->session.prompt.c_str(), on_line);
            return c->session.done ? 1 : 0;
        }
#endif
        const int rc = plain_step(c);
        if (rc) return rc;
        return c->session.done ? 1 : 0;
    });
}

int chm_cmdi_print_async(chm_cmdi_t* c, const char* text) {
    if (!c) return -EINVAL;
    if (!text) return fail(c, -EINVAL, "chm_cmdi_print_async: NULL text");
    return guarded(c, [&] {
        const std::size_t len = std::strlen(text);
        const bool nl = len > 0 && text[len - 1] == '\n';
        if (g_session != c || c->session.done || !isatty(STDOUT_FILENO)) {
            FILE* f = g_session == c ? stdout : out(c);
            if (std::fprintf(f, "%s%s", text, nl ? "" : "\n") < 0 || std::fflush(f) != 0)
                return fail(c, -EIO, "chm_cmdi_print_async: writing failed");
            return 0;
        }
        // Back to the first row of the prompt, clear from there down, the
        // text (\r\n: the terminal may be in raw mode), then the prompt and
        // the line again.
        std::string s = "\r";
#ifdef CHM_CMDI_LIBEDIT
        if (c->session.editing) {
            winsize ws{};
            const std::size_t cols = ::ioctl(STDOUT_FILENO, TIOCGWINSZ, &ws) == 0 && ws.ws_col ? ws.ws_col : 80;
            const std::size_t rows = (c->session.prompt.size() + static_cast<std::size_t>(rl_point)) / cols;
            if (rows) s += "\033[" + std::to_string(rows) + "A";
        }
#endif
        s += "\033[J";
        for (std::size_t i = 0; i < len; ++i) s += text[i] == '\n' ? std::string("\r\n") : std::string(1, text[i]);
        if (!nl) s += "\r\n";
        std::fflush(stdout);
        if (std::fputs(s.c_str(), stdout) < 0 || std::fflush(stdout) != 0)
            return fail(c, -EIO, "chm_cmdi_print_async: writing failed");
#ifdef CHM_CMDI_LIBEDIT
        if (c->session.editing) {
            rl_forced_update_display();
            return 0;
        }
#endif
        plain_prompt(c);
        return 0;
    });
}

int chm_cmdi_interactive_end(chm_cmdi_t* c) {
    if (!c) return -EINVAL;
    if (g_session != c) return no_session(c, "chm_cmdi_interactive_end");
#ifdef CHM_CMDI_LIBEDIT
    if (c->session.editing) {
        rl_callback_handler_remove();
        rl_attempted_completion_function = nullptr;
    }
#endif
    std::fflush(stdout);
    g_session = nullptr;
    c->session.active = false;
    return c->history_path.empty() ? 0 : chm_cmdi_history_save(c);
}

int chm_cmdi_loop(chm_cmdi_t* c, const char* prompt) {
    if (!c) return -EINVAL;
    int rc = chm_cmdi_interactive_begin(c, prompt);
    if (rc) return rc;
    for (;;) {
        pollfd p{STDIN_FILENO, POLLIN, 0};
        if (::poll(&p, 1, -1) < 0) {
            if (errno == EINTR) continue;
            rc = failf(c, -EIO, "waiting for stdin: %s", std::strerror(errno));
            break;
        }
        rc = chm_cmdi_interactive_step(c);
        if (rc) break;
    }
    const int end = chm_cmdi_interactive_end(c);
    return rc < 0 ? rc : end;
}

}  // extern "C"
