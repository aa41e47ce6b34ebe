// libFuzzer harness: the command interpreter (chimera/cmdi.h), the parser
// of lines people type and of the scripts they write. The input is a
// script; whatever follows its first "\n===\n" is also written to a.cmd in
// the harness's scratch directory (the working directory while an input
// runs), so `source a.cmd` (and a.cmd sourcing
// itself, or b.cmd, which sources a.cmd) reaches nested scripts and the
// depth limit. The first byte's low bit turns keep-going on. Checked:
// every status is one the API documents or a harness command returned;
// every failure's message names the script and a line; argv is
// NULL-terminated and starts with the full command name; a suggestion is
// a registered name; and each line that splits re-splits, after its words
// are single-quoted again, into the same words.
#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "chimera/cmdi.h"
#include "lib/cmdi/cmdi.hpp"

namespace {

void expect(bool ok) {
    if (!ok) std::abort();
}

const char* const kNames[] = {"w", "status", "stats", "step", "stop", "fail", "nest", "say"};

std::string g_dir;
int g_cwd = -1;  // libFuzzer's working directory (its corpus paths are relative)
FILE* g_null = nullptr;

void write_file(const std::string& name, const std::string& text) {
    FILE* f = std::fopen((g_dir + "/" + name).c_str(), "wb");
    expect(f != nullptr);
    std::fwrite(text.data(), 1, text.size(), f);
    std::fclose(f);
}

void remove_dir() {
    for (const char* n : {"a.cmd", "b.cmd", "status.help"}) unlink((g_dir + "/" + n).c_str());
    rmdir(g_dir.c_str());
}

void setup() {
    const char* tmp = std::getenv("TMPDIR");
    std::string tmpl = std::string(tmp && *tmp ? tmp : "/tmp") + "/chm-fuzz-cmdi-XXXXXX";
    expect(mkdtemp(tmpl.data()) != nullptr);
    g_dir = tmpl;
    g_cwd = open(".", O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    expect(g_cwd >= 0);
    std::atexit(remove_dir);
    write_file("b.cmd", "w b\nsource a.cmd\n");
    write_file("status.help", "[not a section]\nThe state of things.\n");
    g_null = std::fopen("/dev/null", "w");
    expect(g_null != nullptr);
}

// Records nothing; checks what every command gets.
int command(chm_cmdi_t* c, int argc, char** argv, void*) {
    expect(argc >= 1 && argv[argc] == nullptr);
    bool known = false;
    for (const char* n : kNames) known = known || std::strcmp(argv[0], n) == 0;
    expect(known);
    if (!std::strcmp(argv[0], "fail")) return 2000 + (argc > 1 ? std::abs(std::atoi(argv[1]) % 1000) : 0);
    if (!std::strcmp(argv[0], "say"))
        return chm_cmdi_error(c, -ERANGE, "%s", argc > 1 ? argv[1] : "nothing to say");
    if (!std::strcmp(argv[0], "nest")) return argc > 1 ? chm_cmdi_run_line(c, argv[1]) : 0;
    return chm_cmdi_printf(c, "%s %d\n", argv[0], argc) > 0 ? 0 : -EIO;
}

// Statuses the API documents (negative errnos: a script's file may fail
// with any of open's), and the ones `fail` returns (2000..2999). The shell
// escape is not allowed, so no exit status of a shell can come back.
bool documented(int rc) { return rc == 0 || (rc > -4096 && rc < 0) || (rc >= 2000 && rc < 3000); }

std::string requote(const std::vector<std::string>& words) {
    std::string line;
    for (const std::string& w : words) {
        line += line.empty() ? "'" : " '";
        for (char ch : w) line += ch == '\'' ? std::string("'\\''") : std::string(1, ch);
        line += "'";
    }
    return line;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (g_dir.empty()) setup();
    // Scripts name a.cmd and b.cmd relative to the scratch directory.
    expect(chdir(g_dir.c_str()) == 0);
    const std::string input(reinterpret_cast<const char*>(data), size);
    const std::size_t sep = input.find("\n===\n");
    write_file("a.cmd", sep == std::string::npos ? "" : input.substr(sep + 5));

    chm_cmdi_t* c = chm_cmdi_create("fuzz");
    expect(c != nullptr);
    for (const char* n : kNames) expect(chm_cmdi_add(c, n, command, nullptr, "[ARG]...", "a harness command") == 0);
    expect(chm_cmdi_set_output(c, g_null) == 0);
    expect(chm_cmdi_help_path(c, g_dir.c_str()) == 0);
    expect(chm_cmdi_keep_going(c, size > 0 && (data[0] & 1)) == 0);

    const int rc = chm_cmdi_run_text(c, input.data(), input.size(), "f.cmd");
    expect(documented(rc));
    if (rc != 0) expect(std::strncmp(chm_cmdi_last_error(c), "f.cmd:", 6) == 0);

    // Line by line: the splitter's round trip, suggestions, history.
    std::size_t pos = 0;
    for (int lines = 0; pos <= input.size() && lines < 64; ++lines) {
        std::size_t nl = input.find('\n', pos);
        if (nl == std::string::npos) nl = input.size();
        const std::string line = input.substr(pos, nl - pos);
        pos = nl + 1;
        std::vector<std::string> words, again;
        std::string err;
        if (chm::cmdi::split(line, words, err) != 0) {
            expect(err.find("column ") != std::string::npos);
            continue;
        }
        expect(chm::cmdi::split(requote(words), again, err) == 0 && again == words);
        if (!words.empty()) {
            char buf[CHM_CMDI_NAME_MAX + 1];
            const int s = chm_cmdi_suggest(c, words[0].c_str(), buf, sizeof buf);
            expect(s == 0 || s == -ENOENT);
            if (s == 0) expect(chm_cmdi_run_line(c, (std::string("help ") + buf).c_str()) == 0);
        }
        const int h = chm_cmdi_history_add(c, line.c_str());
        expect(h == 0 || (h == -EINVAL && line.find('\n') != std::string::npos));
    }
    expect(chm_cmdi_run_line(c, "history 3") == 0);
    chm_cmdi_destroy(c);
    expect(fchdir(g_cwd) == 0);
    return 0;
}
