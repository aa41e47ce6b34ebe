// Suite `cmdi`: interactive sessions through a pseudo-terminal. A child
// made by forkpty runs chm_cmdi_loop (or the event-driven calls with
// chm_cmdi_print_async) on the terminal's slave side; the test types at
// the master side and reads what the terminal shows: a mistyped command's
// suggestion, tab completion and history recall (with libedit), text
// printed above a half-typed line that survives it, and the history file
// written at the end. Every wait is bounded; the child is killed and
// reaped whatever happens.
#include <fcntl.h>
#include <poll.h>
#include <pty.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <fstream>
#include <sstream>

#include "../private_dir.hpp"
#include "cmdi_test.hpp"
#include "../pty_driver.hpp"

namespace {

using chm::test::kWaitMs;
using chm::test::Pty;

int status_cmd(chm_cmdi_t* c, int, char**, void*) { return chm_cmdi_printf(c, "status: all well\n") > 0 ? 0 : 1; }

chm_cmdi_t* child_interpreter(const std::string& history) {
    chm_cmdi_t* c = chm_cmdi_create("t");
    if (!c || chm_cmdi_add(c, "status", status_cmd, nullptr, nullptr, "show the state") ||
        chm_cmdi_add(c, "stop", status_cmd, nullptr, nullptr, "stop it") ||
        chm_cmdi_history_file(c, history.c_str()))
        _exit(20);
    return c;
}

std::string slurp(const std::string& path) {
    std::ifstream in(path);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
}

class CmdiPty : public ::testing::Test {
protected:
    void SetUp() override {
        dir = chm::test::make_private_dir("chm-cmdi-pty-");
        ASSERT_FALSE(dir.empty());
        history = dir + "/history";
    }
    void TearDown() override { chm::test::remove_private_dir(dir); }
    std::string dir, history;
};

TEST_F(CmdiPty, LoopSuggestsCompletesRecallsAndSavesHistory) {
    Pty t;
    const std::string hist = history;
    ASSERT_TRUE(t.start([&] {
        chm_cmdi_t* c = child_interpreter(hist);
        const int rc = chm_cmdi_loop(c, "t> ");
        chm_cmdi_destroy(c);
        return rc == 0 ? 0 : 10;
    }));
    ASSERT_TRUE(t.read_until("t> ")) << t.seen;
    t.type("stauts\r");
    ASSERT_TRUE(t.read_until("t: unknown command 'stauts'; did you mean 'status'?")) << t.seen;
    ASSERT_TRUE(t.read_until("t> ")) << t.seen;
    const bool editing = chm_cmdi_has_line_editing();
    if (editing) {
        t.type("sta\t");  // completes to the one name it begins: "status "
        ASSERT_TRUE(t.read_until("tus")) << t.seen;
        t.type("\r");
        ASSERT_TRUE(t.read_until("status: all well")) << t.seen;
        ASSERT_TRUE(t.read_until("t> ")) << t.seen;
        t.type("\033[A\r");  // up arrow: the last line again
        ASSERT_TRUE(t.read_until("status: all well")) << t.seen;
        ASSERT_TRUE(t.read_until("t> ")) << t.seen;
        t.type("help st\t\t");  // after "help": command names; two tabs list the candidates
        ASSERT_TRUE(t.read_until("status")) << t.seen;
        ASSERT_TRUE(t.read_until("stop")) << t.seen;
        t.type("\025");  // ^U: kill the line
        // Past the first word: file names.
        std::ofstream(dir + "/script.cmd") << "status\n";
        t.type("source " + dir + "/scr\t");
        ASSERT_TRUE(t.read_until("ipt.cmd")) << t.seen;
        t.type("\025");
    } else {
        t.type("status\r");
        ASSERT_TRUE(t.read_until("status: all well")) << t.seen;
        ASSERT_TRUE(t.read_until("t> ")) << t.seen;
    }
    t.type("quit\r");
    EXPECT_EQ(t.wait_exit(), 0) << t.seen;
    // Completion left a blank after "status", not kept; the recalled line
    // repeats the last entry, not added again.
    EXPECT_EQ(slurp(history), "stauts\nstatus\nquit\n");
}

TEST_F(CmdiPty, EndOfInputEndsTheLoop) {
    Pty t;
    const std::string hist = history;
    ASSERT_TRUE(t.start([&] {
        chm_cmdi_t* c = child_interpreter(hist);
        const int rc = chm_cmdi_loop(c, nullptr);  // default prompt "t> "
        chm_cmdi_destroy(c);
        return rc == 0 ? 0 : 10;
    }));
    ASSERT_TRUE(t.read_until("t> ")) << t.seen;
    t.type("status\r");
    ASSERT_TRUE(t.read_until("status: all well")) << t.seen;
    ASSERT_TRUE(t.read_until("t> ")) << t.seen;
    t.type("\004");  // ^D on an empty line
    EXPECT_EQ(t.wait_exit(), 0) << t.seen;
    EXPECT_EQ(slurp(history), "status\n");
}

TEST_F(CmdiPty, AsyncTextAboveAHalfTypedLine) {
    int ctl[2];
    ASSERT_EQ(pipe(ctl), 0);
    Pty t;
    const std::string hist = history;
    ASSERT_TRUE(t.start([&] {
        close(ctl[1]);
        chm_cmdi_t* c = child_interpreter(hist);
        if (chm_cmdi_interactive_begin(c, "t> ")) return 11;
        chm_cmdi_t* other = chm_cmdi_create("u");
        if (chm_cmdi_interactive_begin(other, nullptr) != -EBUSY) return 12;
        chm_cmdi_destroy(other);
        const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(kWaitMs);
        int rc = 0;
        while (rc == 0 && std::chrono::steady_clock::now() < end) {
            pollfd p[2] = {{STDIN_FILENO, POLLIN, 0}, {ctl[0], POLLIN, 0}};
            if (poll(p, 2, 100) <= 0) continue;
            if (p[1].revents & POLLIN) {
                char msg[256];
                const ssize_t n = read(ctl[0], msg, sizeof msg - 1);
                if (n <= 0) return 13;
                msg[n] = 0;
                if (!std::strcmp(msg, "QUIT")) {
                    // Between lines: the next step ends the session
                    // without reading (stdin has nothing: it would block).
                    if (chm_cmdi_quit(c)) return 17;
                    rc = chm_cmdi_interactive_step(c);
                    continue;
                }
                if (chm_cmdi_print_async(c, msg)) return 14;
            }
            if (p[0].revents) rc = chm_cmdi_interactive_step(c);
        }
        if (chm_cmdi_interactive_end(c)) return 15;
        chm_cmdi_destroy(c);
        return rc == 1 ? 0 : 16;
    }));
    close(ctl[0]);
    ASSERT_TRUE(t.read_until("t> ")) << t.seen;
    t.type("sta");
    ASSERT_TRUE(t.read_until("sta")) << t.seen;
    const std::string msg = "remote: task 3 says hello\nremote: and goodbye";
    ASSERT_EQ(write(ctl[1], msg.data(), msg.size()), ssize_t(msg.size()));
    // From the start of the prompt's row, cleared to the end of the screen.
    ASSERT_TRUE(t.read_until("\r\033[Jremote: task 3 says hello\r")) << t.seen;
    ASSERT_TRUE(t.read_until("\nremote: and goodbye\r")) << t.seen;
    // libedit redraws the prompt and the half-typed line below the text;
    // plain reading can only show the prompt (the kernel holds the line).
    ASSERT_TRUE(t.read_until(chm_cmdi_has_line_editing() ? "t> sta" : "t> ")) << t.seen;
    t.type("tus\r");  // the line typed before the text was printed goes on
    ASSERT_TRUE(t.read_until("status: all well")) << t.seen;
    ASSERT_TRUE(t.read_until("t> ")) << t.seen;
    ASSERT_EQ(write(ctl[1], "QUIT", 4), 4);
    EXPECT_EQ(t.wait_exit(), 0) << t.seen;
    close(ctl[1]);
    EXPECT_EQ(slurp(history), "status\n");
}

TEST(CmdiSession, CallsOutsideASession) {
    chm::test::Cmdi t;
    EXPECT_EQ(chm_cmdi_interactive_step(t.c), -EINVAL);
    EXPECT_EQ(t.err(), "chm_cmdi_interactive_step: t has no interactive session");
    EXPECT_EQ(chm_cmdi_interactive_end(t.c), -EINVAL);
    EXPECT_EQ(chm_cmdi_print_async(t.c, "to the output"), 0);  // no session: the output stream
    EXPECT_EQ(t.out(), "to the output\n");
    EXPECT_EQ(chm_cmdi_print_async(t.c, nullptr), -EINVAL);
}

}  // namespace
