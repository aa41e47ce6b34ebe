// Scripts, help and the built-in commands of the command interpreter
// (chimera/cmdi.h): help, source, history, quit, exit.
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cstring>

#include "cmdi.hpp"

namespace chm::cmdi {

int read_file(chm_cmdi* c, const std::string& path, std::size_t max, std::string& data) {
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
    if (fd < 0) {
        const int e = errno;
        return failf(c, -e, "cannot open '%s': %s", printable(path).c_str(), std::strerror(e));
    }
    struct stat st {};
    int rc = 0;
    if (::fstat(fd, &st) < 0) {
        rc = failf(c, -errno, "cannot stat '%s': %s", printable(path).c_str(), std::strerror(errno));
    } else if (S_ISDIR(st.st_mode)) {
        rc = failf(c, -EISDIR, "'%s' is a directory", printable(path).c_str());
    } else if (!S_ISREG(st.st_mode)) {
        rc = failf(c, -EINVAL, "'%s' is not a regular file", printable(path).c_str());
    } else if (static_cast<std::size_t>(st.st_size) > max) {
        rc = failf(c, -EFBIG, "'%s' is larger than %zu bytes", printable(path).c_str(), max);
    }
    data.clear();
    char buf[8192];
    while (rc == 0) {
        const ssize_t n = ::read(fd, buf, sizeof buf);
        if (n == 0) break;
        if (n < 0) {
            if (errno == EINTR) continue;
            rc = failf(c, -errno, "cannot read '%s': %s", printable(path).c_str(), std::strerror(errno));
        } else if (data.size() + static_cast<std::size_t>(n) > max) {
            rc = failf(c, -EFBIG, "'%s' is larger than %zu bytes", printable(path).c_str(), max);
        } else {
            data.append(buf, static_cast<std::size_t>(n));
        }
    }
    ::close(fd);
    return rc;
}

bool help_text(const chm_cmdi* c, const std::string& topic, std::string& text) {
    if (c->help_path.empty() || !check_name(topic.c_str(), false).empty()) return false;
    struct stat st {};
    if (::stat(c->help_path.c_str(), &st) < 0) return false;
    std::string data;
    if (S_ISDIR(st.st_mode)) {
        if (read_file(nullptr, c->help_path + "/" + topic + ".help", 1u << 20, data)) return false;
        text = data;
        return true;
    }
    if (read_file(nullptr, c->help_path, 4u << 20, data)) return false;
    const std::string head = "[" + topic + "]";
    bool in = false, found = false;
    std::size_t pos = 0;
    while (pos < data.size()) {
        std::size_t nl = data.find('\n', pos);
        if (nl == std::string::npos) nl = data.size();
        std::string line = data.substr(pos, nl - pos);
        pos = nl + 1;
        if (!line.empty() && line.back() == '\r') line.pop_back();
        if (!line.empty() && line[0] == '[') {
            if (in) break;
            in = line == head;
            found = found || in;
            continue;
        }
        if (in) text += line + "\n";
    }
    while (text.size() >= 2 && text.compare(text.size() - 2, 2, "\n\n") == 0) text.pop_back();
    return found;
}

namespace {

int usage_error(chm_cmdi* c, const char* name) {
    const auto it = c->commands.find(name);
    const std::string usage = it == c->commands.end() ? "" : it->second.usage;
    return failf(c, -EINVAL, "usage: %s%s%s", name, usage.empty() ? "" : " ", usage.c_str());
}

// The first line of a help text.
std::string first_line(const std::string& s) { return s.substr(0, s.find('\n')); }

void list_commands(chm_cmdi* c) {
    std::size_t width = 0;
    for (const auto& [name, cmd] : c->commands)
        width = std::max(width, name.size() + (cmd.usage.empty() ? 0 : 1 + cmd.usage.size()));
    width = std::min<std::size_t>(width, 28);
    FILE* f = out(c);
    std::fprintf(f, "Commands (any unique prefix of a name runs it; 'help CMD' describes one):\n");
    for (const auto& [name, cmd] : c->commands) {
        const std::string left = name + (cmd.usage.empty() ? "" : " " + cmd.usage);
        const std::string line = first_line(cmd.help);
        if (line.empty())
            std::fprintf(f, "  %s\n", left.c_str());
        else if (left.size() > width)
            std::fprintf(f, "  %s\n  %*s  %s\n", left.c_str(), static_cast<int>(width), "", line.c_str());
        else
            std::fprintf(f, "  %-*s  %s\n", static_cast<int>(width), left.c_str(), line.c_str());
    }
    if (c->allow_shell) std::fprintf(f, "  %-*s  %s\n", static_cast<int>(width), "!CMD", "run CMD with /bin/sh");
}

int help(chm_cmdi_t* c, int argc, char** argv, void*) {
    if (argc == 1) {
        list_commands(c);
        return 0;
    }
    if (argc > 2) return usage_error(c, argv[0]);
    const std::string topic = argv[1];
    const auto it = c->commands.find(resolve(c, topic));
    std::string extra;
    const bool has_extra = help_text(c, it == c->commands.end() ? topic : it->first, extra);
    FILE* f = out(c);
    if (it == c->commands.end()) {
        if (has_extra) {
            std::fputs(extra.c_str(), f);
            if (!extra.empty() && extra.back() != '\n') std::fputc('\n', f);
            return 0;
        }
        // Unknown or ambiguous: say which.
        char near[CHM_CMDI_NAME_MAX + 1];
        std::string msg = "no help for '" + printable(topic) + "'";
        std::string cands;
        for (auto p = c->commands.lower_bound(topic);
             p != c->commands.end() && p->first.compare(0, topic.size(), topic) == 0; ++p)
            cands += (cands.empty() ? "" : ", ") + p->first;
        if (!cands.empty())
            msg += ": ambiguous, it begins " + cands;
        else if (chm_cmdi_suggest(c, topic.c_str(), near, sizeof near) == 0)
            msg += std::string("; did you mean '") + near + "'?";
        return fail(c, -ENOENT, msg);
    }
    const chm::cmdi::Command& cmd = it->second;
    std::fprintf(f, "usage: %s%s%s\n", it->first.c_str(), cmd.usage.empty() ? "" : " ", cmd.usage.c_str());
    if (!cmd.help.empty()) std::fprintf(f, "%s%s", cmd.help.c_str(), cmd.help.back() == '\n' ? "" : "\n");
    if (has_extra && !extra.empty())
        std::fprintf(f, "\n%s%s", extra.c_str(), extra.back() == '\n' ? "" : "\n");
    return 0;
}

int source(chm_cmdi_t* c, int argc, char** argv, void*) {
    if (argc != 2) return usage_error(c, argv[0]);
    return chm_cmdi_run_script(c, argv[1]);
}

int history(chm_cmdi_t* c, int argc, char** argv, void*) {
    if (argc > 2) return usage_error(c, argv[0]);
    std::size_t from = 0;
    if (argc == 2) {
        char* end = nullptr;
        errno = 0;
        const unsigned long n = std::strtoul(argv[1], &end, 10);
        if (errno || end == argv[1] || *end || argv[1][0] == '-')
            return failf(c, -EINVAL, "history: COUNT must be a number, not '%s'", printable(argv[1]).c_str());
        if (n < c->history.size()) from = c->history.size() - n;
    }
    for (std::size_t i = from; i < c->history.size(); ++i)
        std::fprintf(out(c), "%5zu  %s\n", i + 1, c->history[i].c_str());
    return 0;
}

int quit(chm_cmdi_t* c, int argc, char** argv, void*) {
    if (argc != 1) return usage_error(c, argv[0]);
    c->quit = true;
    return 0;
}

}  // namespace

void add_builtins(chm_cmdi* c) {
    c->commands["help"] = {help, nullptr, "[CMD]",
                           "list the commands, or describe one\n"
                           "With CMD (a command, any unique prefix of one, or a help topic): its\n"
                           "usage, its description and its help file, when there is one."};
    c->commands["source"] = {source, nullptr, "FILE",
                             "run the commands in FILE, one a line\n"
                             "Stops at the first failing line, naming FILE:LINE and what failed."};
    c->commands["history"] = {history, nullptr, "[COUNT]",
                              "list the lines entered (the last COUNT of them)"};
    c->commands["quit"] = {quit, nullptr, "", "leave the command line (the same as exit)"};
    c->commands["exit"] = {quit, nullptr, "", "leave the command line (the same as quit)"};
}

}  // namespace chm::cmdi

using namespace chm::cmdi;

extern "C" {

int chm_cmdi_help_path(chm_cmdi_t* c, const char* path) {
    if (!c) return -EINVAL;
    return guarded(c, [&] {
        if (!path) {
            c->help_path.clear();
            return 0;
        }
        struct stat st {};
        if (::stat(path, &st) < 0)
            return failf(c, -errno, "help path '%s': %s", printable(path).c_str(), std::strerror(errno));
        c->help_path = path;
        return 0;
    });
}

int chm_cmdi_run_text(chm_cmdi_t* c, const char* text, size_t len, const char* name) {
    if (!c) return -EINVAL;
    if (!text && len) return fail(c, -EINVAL, "chm_cmdi_run_text: NULL text");
    return guarded(c, [&] {
        const std::string label = name ? name : "<string>";
        if (c->script_depth >= CHM_CMDI_SOURCE_DEPTH)
            return failf(c, -ELOOP, "%s: scripts nested deeper than %d (a script sourcing itself?)",
                         printable(label).c_str(), CHM_CMDI_SOURCE_DEPTH);
        if (c->depth == 0 && c->script_depth == 0) c->quit = false;
        struct Guard {
            chm_cmdi* c;
            ~Guard() { --c->script_depth; }
        } guard{c};
        ++c->script_depth;
        int first_rc = 0;
        std::string first_err;
        std::size_t pos = 0, lineno = 0;
        while (pos < len && !c->quit) {
            const char* nl = static_cast<const char*>(std::memchr(text + pos, '\n', len - pos));
            const std::size_t end = nl ? static_cast<std::size_t>(nl - text) : len;
            std::string line(text + pos, end - pos);
            pos = end + 1;
            ++lineno;
            if (!line.empty() && line.back() == '\r') line.pop_back();
            const std::size_t nul = line.find('\0');
            const int rc = nul != std::string::npos
                               ? failf(c, -EINVAL, "NUL byte at column %zu", nul + 1)
                               : chm_cmdi_run_line(c, line.c_str());
            if (rc == 0) continue;
            const std::string msg = label + ":" + std::to_string(lineno) + ": " + c->error;
            if (!c->keep_going) return fail(c, rc, msg);
            std::fprintf(out(c), "%s\n", msg.c_str());
            if (first_rc == 0) {
                first_rc = rc;
                first_err = msg;
            }
        }
        return first_rc ? fail(c, first_rc, first_err) : 0;
    });
}

int chm_cmdi_run_script(chm_cmdi_t* c, const char* path) {
    if (!c) return -EINVAL;
    if (!path) return fail(c, -EINVAL, "chm_cmdi_run_script: NULL path");
    return guarded(c, [&] {
        if (c->script_depth >= CHM_CMDI_SOURCE_DEPTH)
            return failf(c, -ELOOP, "%s: scripts nested deeper than %d (a script sourcing itself?)",
                         printable(path).c_str(), CHM_CMDI_SOURCE_DEPTH);
        std::string data;
        const int rc = read_file(c, path, kMaxScript, data);
        if (rc) return rc;
        return chm_cmdi_run_text(c, data.data(), data.size(), path);
    });
}

}  // extern "C"
