// Internals of the command interpreter (chimera/cmdi.h), shared by
// words.cpp (the line splitter), core.cpp (commands, errors, running a
// line), script.cpp (scripts, help, built-ins) and interactive.cpp
// (sessions, history, libedit).
#pragma once

#include <cerrno>
#include <cstdio>
#include <map>
#include <new>
#include <string>
#include <string_view>
#include <vector>

#include "chimera/cmdi.h"

namespace chm::cmdi {

struct Command {
    chm_cmdi_fn fn = nullptr;
    void* user = nullptr;
    std::string usage;
    std::string help;
};

// One interactive session's state (at most one per process).
struct Session {
    bool active = false;
    bool editing = false;   // libedit drives the terminal
    bool done = false;      // quit or end of input seen
    bool line_read = false; // libedit called on_line during this step
    std::string prompt;
    std::string pending;    // plain reading: bytes of a line not yet ended
};

}  // namespace chm::cmdi

struct chm_cmdi {
    std::string name;
    std::map<std::string, chm::cmdi::Command> commands;  // sorted: listing, prefixes
    FILE* out = nullptr;  // nullptr: stdout
    bool allow_shell = false;
    bool keep_going = false;
    bool quit = false;
    std::string help_path;
    std::vector<std::string> history;
    std::string history_path;
    int depth = 0;         // run_line calls in progress
    int script_depth = 0;  // scripts in progress
    std::string error;
    bool error_set = false;  // chm_cmdi_error called since the flag was cleared
    chm::cmdi::Session session;
};

namespace chm::cmdi {

constexpr int kMaxLineDepth = 32;
constexpr std::size_t kMaxScript = 16u << 20;

// Sets c's last-error text; returns `status`. Never throws.
int fail(chm_cmdi* c, int status, const std::string& msg) noexcept;
int failf(chm_cmdi* c, int status, const char* fmt, ...) noexcept
    __attribute__((format(printf, 3, 4)));

FILE* out(const chm_cmdi* c);

// Splits `line` into words (the rules of cmdi.h). Returns 0, or -EINVAL
// with `err` set to the message (naming the 1-based column).
int split(std::string_view line, std::vector<std::string>& words, std::string& err);

// `s` as messages quote it: control and non-ASCII bytes as \xHH, at most
// 60 bytes of it (then "...").
std::string printable(std::string_view s);

// Reads the regular file at `path` (at most `max` bytes) into `data`.
// Errors (message set, naming `path`): -errno of open/read; -EISDIR;
// -EINVAL not a regular file; -EFBIG larger than `max`.
int read_file(chm_cmdi* c, const std::string& path, std::size_t max, std::string& data);

// A name as cmdi.h allows for commands (is_command) or interpreters; ""
// when good, else what is wrong with it.
std::string check_name(const char* name, bool is_command);

// Optimal-string-alignment distance (Damerau-Levenshtein with adjacent
// transpositions), ignoring ASCII case.
std::size_t distance(std::string_view a, std::string_view b);

// The command `word` names, exactly or as the prefix of only one name;
// "" when none or several.
std::string resolve(const chm_cmdi* c, const std::string& word);

// Registers help, source, history, quit, exit.
void add_builtins(chm_cmdi* c);

// The extra help text for `topic` from the help path; false when none.
bool help_text(const chm_cmdi* c, const std::string& topic, std::string& text);

// Runs `body`, turning any exception into a status.
template <typename F>
int guarded(chm_cmdi* c, F&& body) noexcept {
    try {
        return body();
    } catch (const std::bad_alloc&) {
        return fail(c, -ENOMEM, "out of memory");
    } catch (...) {
        return fail(c, -EIO, "internal error in the command interpreter");
    }
}

}  // namespace chm::cmdi
