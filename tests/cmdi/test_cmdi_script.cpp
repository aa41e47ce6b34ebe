// Suite `cmdi`: scripts (file:line errors, keep-going, quit, nested source
// and its depth limit), the shell escape (refused, allowed, exit status,
// signals) and the history with its file (chimera/cmdi.h).
#include <sys/stat.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>

#include "../private_dir.hpp"
#include "cmdi_test.hpp"

namespace {

using chm::test::Cmdi;
using Words = std::vector<std::string>;

int run_text(Cmdi& t, const std::string& text, const char* name = "s.cmd") {
    return chm_cmdi_run_text(t.c, text.data(), text.size(), name);
}

TEST(CmdiScript, RunsLineByLine) {
    Cmdi t;
    t.add_recorder("w");
    EXPECT_EQ(run_text(t, "w a\n# comment\n\n  w 'b c'\r\nw d"), 0) << t.err();
    EXPECT_EQ(t.calls, (std::vector<Words>{{"w", "a"}, {"w", "b c"}, {"w", "d"}}));
    EXPECT_EQ(run_text(t, ""), 0);
    EXPECT_EQ(chm_cmdi_run_text(t.c, nullptr, 0, nullptr), 0);
    EXPECT_EQ(chm_cmdi_run_text(t.c, nullptr, 1, nullptr), -EINVAL);
}

TEST(CmdiScript, StopsAtTheFirstFailingLineNamingIt) {
    Cmdi t;
    t.add_recorder("w");
    EXPECT_EQ(run_text(t, "w 1\nw fail 3\nw 2\n"), 3);
    EXPECT_EQ(t.err(), "s.cmd:2: w failed with status 3");
    EXPECT_EQ(t.calls.size(), 2u);
    EXPECT_EQ(run_text(t, "w ok\n\nw \"x\n", nullptr), -EINVAL);
    EXPECT_EQ(t.err(), "<string>:3: unterminated double quote opened at column 3");
    EXPECT_EQ(run_text(t, "wx\n"), -ENOENT);
    EXPECT_EQ(t.err(), "s.cmd:1: unknown command 'wx'; did you mean 'w'?");
    EXPECT_EQ(run_text(t, std::string("w\nw a\0b\n", 8)), -EINVAL);
    EXPECT_EQ(t.err(), "s.cmd:2: NUL byte at column 4");
}

TEST(CmdiScript, KeepGoingPrintsEachFailureReturnsTheFirst) {
    Cmdi t;
    t.add_recorder("w");
    ASSERT_EQ(chm_cmdi_keep_going(t.c, 1), 0);
    EXPECT_EQ(chm_cmdi_keep_going(t.c, 2), -EINVAL);
    EXPECT_EQ(run_text(t, "w fail 5\nw ok\nnope\nw fail 6\n"), 5);
    EXPECT_EQ(t.err(), "s.cmd:1: w failed with status 5");
    EXPECT_EQ(t.out(),
              "s.cmd:1: w failed with status 5\n"
              "s.cmd:3: unknown command 'nope'; 'help' lists the commands\n"
              "s.cmd:4: w failed with status 6\n");
    EXPECT_EQ(t.calls.size(), 3u);
}

TEST(CmdiScript, QuitStopsTheScript) {
    Cmdi t;
    t.add_recorder("w");
    EXPECT_EQ(run_text(t, "w 1\nquit\nw 2\n"), 0);
    EXPECT_EQ(t.calls.size(), 1u);
    EXPECT_EQ(run_text(t, "w 3\n"), 0);  // the next script starts afresh
    EXPECT_EQ(t.calls.size(), 2u);
    EXPECT_EQ(run_text(t, "quit now\n"), -EINVAL);
    EXPECT_EQ(t.err(), "s.cmd:1: usage: quit");
}

TEST(CmdiScript, CommandsRunningLinesAreBounded) {
    Cmdi t;
    auto self = [](chm_cmdi_t* c, int, char**, void*) { return chm_cmdi_run_line(c, "again"); };
    ASSERT_EQ(chm_cmdi_add(t.c, "again", self, nullptr, nullptr, nullptr), 0);
    EXPECT_EQ(t.run("again"), -ELOOP);
    EXPECT_EQ(t.err(), "lines run by commands are nested 32 deep (a command running itself?)");
}

class CmdiFiles : public ::testing::Test {
protected:
    void SetUp() override {
        dir = chm::test::make_private_dir("chm-cmdi-");
        ASSERT_FALSE(dir.empty());
    }
    void TearDown() override { chm::test::remove_private_dir(dir); }
    std::string write(const std::string& name, const std::string& text) {
        std::ofstream(dir + "/" + name) << text;
        return dir + "/" + name;
    }
    std::string dir;
};

TEST_F(CmdiFiles, NestedSourceNamesEachFileAndLine) {
    Cmdi t;
    t.add_recorder("w");
    const std::string b = write("b.cmd", "w b1\nw fail 4\nw b3\n");
    const std::string a = write("a.cmd", "w a1\nsource " + b + "\nw a3\n");
    EXPECT_EQ(chm_cmdi_run_script(t.c, a.c_str()), 4);
    EXPECT_EQ(t.err(), a + ":2: " + b + ":2: w failed with status 4");
    EXPECT_EQ(t.calls, (std::vector<Words>{{"w", "a1"}, {"w", "b1"}, {"w", "fail", "4"}}));
    t.calls.clear();
    const std::string ok = write("ok.cmd", "w x\n");
    EXPECT_EQ(t.run("sou " + ok), 0) << t.err();
    EXPECT_EQ(t.calls, (std::vector<Words>{{"w", "x"}}));
}

TEST_F(CmdiFiles, RecursionStopsAtTheDepthLimit) {
    Cmdi t;
    t.add_recorder("w");
    const std::string r = dir + "/r.cmd";
    write("r.cmd", "w r\nsource " + r + "\n");
    EXPECT_EQ(chm_cmdi_run_script(t.c, r.c_str()), -ELOOP);
    std::string want;
    for (int i = 0; i < CHM_CMDI_SOURCE_DEPTH; ++i) want += r + ":2: ";
    want += r + ": scripts nested deeper than 8 (a script sourcing itself?)";
    EXPECT_EQ(t.err(), want);
    EXPECT_EQ(t.calls.size(), static_cast<std::size_t>(CHM_CMDI_SOURCE_DEPTH));
    // The depth is restored: the same interpreter runs scripts again.
    const std::string ok = write("ok.cmd", "w fine\n");
    EXPECT_EQ(chm_cmdi_run_script(t.c, ok.c_str()), 0) << t.err();
}

TEST_F(CmdiFiles, FilesThatAreNoScripts) {
    Cmdi t;
    EXPECT_EQ(chm_cmdi_run_script(t.c, (dir + "/none.cmd").c_str()), -ENOENT);
    EXPECT_EQ(t.err(), "cannot open '" + dir + "/none.cmd': No such file or directory");
    EXPECT_EQ(chm_cmdi_run_script(t.c, dir.c_str()), -EISDIR);
    EXPECT_EQ(t.err(), "'" + dir + "' is a directory");
    const std::string fifo = dir + "/fifo";
    ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
    EXPECT_EQ(t.run("source " + fifo), -EINVAL);  // would block: refused
    EXPECT_EQ(t.err(), "'" + fifo + "' is not a regular file");
    EXPECT_EQ(t.run("source"), -EINVAL);
    EXPECT_EQ(t.err(), "usage: source FILE");
    EXPECT_EQ(chm_cmdi_run_script(t.c, nullptr), -EINVAL);
}

TEST(CmdiShell, RefusedUnlessAllowed) {
    Cmdi t;
    EXPECT_EQ(t.run("!echo hi"), -EPERM);
    EXPECT_EQ(t.err(), "shell escape refused: t does not allow shell commands ('!echo hi')");
    EXPECT_EQ(t.out(), "");
    EXPECT_EQ(chm_cmdi_allow_shell(t.c, 7), -EINVAL);
}

TEST(CmdiShell, RunsThroughShWaitsAndReturnsTheExitStatus) {
    Cmdi t;
    ASSERT_EQ(chm_cmdi_allow_shell(t.c, 1), 0);
    EXPECT_EQ(t.run("  !  echo hi   there; echo err >&2  "), 0) << t.err();
    EXPECT_EQ(t.out(), "hi there\nerr\n");  // stdout and stderr on the output stream
    EXPECT_EQ(t.run("!exit 3"), 3);
    EXPECT_EQ(t.err(), "!exit 3: exit status 3");
    EXPECT_EQ(t.run("!kill -TERM $$"), 128 + SIGTERM);
    EXPECT_EQ(t.err(), std::string("!kill -TERM $$: killed by signal 15 (") + strsignal(SIGTERM) + ")");
    EXPECT_EQ(t.run("!"), -EINVAL);
    EXPECT_EQ(t.err(), "shell escape: no command after '!'");
    // The shell runs to its end before the line returns.
    EXPECT_EQ(t.run("!sleep 0.2; echo late"), 0);
    EXPECT_EQ(t.out(), "late\n");
    // In a script: its status stops the script like any failure.
    const std::string s = "!true\n!false\n!echo never\n";
    EXPECT_EQ(chm_cmdi_run_text(t.c, s.data(), s.size(), "sh.cmd"), 1);
    EXPECT_EQ(t.err(), "sh.cmd:2: !false: exit status 1");
    EXPECT_EQ(t.out(), "");
}

TEST(CmdiHistory, AddSkipsBlanksAndRepeatsKeepsTheLast) {
    Cmdi t;
    for (const char* l : {"one", "one", "", "  ", "two", "one"}) EXPECT_EQ(chm_cmdi_history_add(t.c, l), 0);
    EXPECT_EQ(chm_cmdi_history_add(t.c, "a\nb"), -EINVAL);
    EXPECT_EQ(chm_cmdi_history_add(t.c, nullptr), -EINVAL);
    EXPECT_EQ(t.run("history"), 0);
    EXPECT_EQ(t.out(), "    1  one\n    2  two\n    3  one\n");
    EXPECT_EQ(t.run("history 2"), 0);
    EXPECT_EQ(t.out(), "    2  two\n    3  one\n");
    EXPECT_EQ(t.run("history -1"), -EINVAL);
    EXPECT_EQ(t.err(), "history: COUNT must be a number, not '-1'");
    for (int i = 0; i < CHM_CMDI_HISTORY_MAX + 5; ++i)
        ASSERT_EQ(chm_cmdi_history_add(t.c, ("l" + std::to_string(i)).c_str()), 0);
    EXPECT_EQ(t.run("history 1"), 0);
    EXPECT_EQ(t.out(), " 1000  l1004\n");
    EXPECT_EQ(t.run("history 1000"), 0);
    EXPECT_EQ(t.out().substr(0, 12), "    1  l5\n  ");
}

TEST_F(CmdiFiles, HistoryFileRoundTrip) {
    const std::string path = dir + "/hist";
    const std::vector<std::string> lines = {"status", "set gain \"2.5\" 'x y'", "größe \\ # not a comment here",
                                            "!ls -l"};
    {
        Cmdi t;
        EXPECT_EQ(chm_cmdi_history_save(t.c), -ENOENT);  // no file set
        ASSERT_EQ(chm_cmdi_history_file(t.c, path.c_str()), 0) << t.err();  // missing: empty
        for (const std::string& l : lines) ASSERT_EQ(chm_cmdi_history_add(t.c, l.c_str()), 0);
        ASSERT_EQ(chm_cmdi_history_save(t.c), 0) << t.err();
    }
    std::ifstream in(path);
    std::stringstream file;
    file << in.rdbuf();
    EXPECT_EQ(file.str(), lines[0] + "\n" + lines[1] + "\n" + lines[2] + "\n" + lines[3] + "\n");
    struct stat st {};
    ASSERT_EQ(stat(path.c_str(), &st), 0);
    EXPECT_EQ(st.st_mode & 0777, 0600u);
    Cmdi t;
    ASSERT_EQ(chm_cmdi_history_add(t.c, "before"), 0);
    ASSERT_EQ(chm_cmdi_history_file(t.c, path.c_str()), 0) << t.err();
    EXPECT_EQ(t.run("history"), 0);
    EXPECT_EQ(t.out(), "    1  before\n    2  " + lines[0] + "\n    3  " + lines[1] + "\n    4  " + lines[2] +
                           "\n    5  " + lines[3] + "\n");
    EXPECT_EQ(chm_cmdi_history_file(t.c, dir.c_str()), -EISDIR);
    EXPECT_EQ(t.err(), "history file: '" + dir + "' is a directory");
    EXPECT_EQ(chm_cmdi_history_file(t.c, ""), -EINVAL);
    // A history file whose directory is gone: the save fails, naming it.
    ASSERT_EQ(chm_cmdi_history_file(t.c, (dir + "/sub/h").c_str()), 0);
    EXPECT_EQ(chm_cmdi_history_save(t.c), -ENOENT);
    EXPECT_EQ(t.err(), "history file '" + dir + "/sub/h': No such file or directory");
}

}  // namespace
