// Control programs as shared objects (chimera/program.h): loaded, main
// spawned with its arguments, its code preemptible, bad objects refused.
#include <cerrno>
#include <string>

#include "chimera/program.h"
#include "gap_ticker.hpp"
#include "kernel_fixture.hpp"

#ifndef CTLPROG_PATH
#error "CTLPROG_PATH names the test control program"
#endif

namespace chm::test {
namespace {

class Program : public KernelTest {};

uint64_t g_program_ran = 0;
int g_program = -1;

void watcher(void*) {
    const uint64_t t0 = chm_time_now();
    int status = 0;
    while (chm_program_status(g_program, &status) == -EAGAIN) chm_task_pause_until(chm_time_now() + kMs);
    g_program_ran = chm_time_now() - t0;
    GapTicker::stop = true;
}

TEST_F(Program, MainRunsAsATaskWithItsArgumentsAndIsPreemptible) {
    start(CHM_SCHED_MUF, false);
    GapTicker::reset();
    const char* argv[] = {"ctlprog", "300", "hello"};
    chm_tid_t main_task = CHM_TID_NONE;
    g_program = chm_program_load(CTLPROG_PATH, 3, argv, nullptr, &main_task);
    ASSERT_GE(g_program, 0) << chm_program_error();
    chm_task_status_t st;
    ASSERT_EQ(chm_task_status(main_task, &st), 0);
    EXPECT_STREQ(st.name, "libctlprog.so");
    int status = 0;
    EXPECT_EQ(chm_program_status(g_program, &status), -EAGAIN);
    // Higher priority than main: it only runs if main's loop is preempted.
    spawn(GapTicker::body, nullptr, "ticker", 5, 2 * kMs, 50 * kUs);
    spawn(watcher, nullptr, "watcher", 4);
    ASSERT_EQ(chm_kernel_run(), 0);
    ASSERT_EQ(chm_program_status(g_program, &status), 0);
    EXPECT_EQ(status, 3 * 100 + 5);
    // Had main's loop not been preempted, the ticker would have stood still
    // for the whole loop (one gap as long as it, then a burst of late
    // cycles).
    EXPECT_GT(GapTicker::cycles, 5);
    EXPECT_LT(GapTicker::max_gap * 3, g_program_ran)
        << "the 2 ms ticker stood still " << GapTicker::max_gap << " ns of the program's " << g_program_ran
        << " ns: main's code was not preemptible";
}

TEST_F(Program, BadObjectsAreRefusedAndNothingStaysLoaded) {
    start(CHM_SCHED_MUF, false);
    // Each message names the file and the cause, once.
    EXPECT_EQ(chm_program_load("/no/such/program.so", 0, nullptr, nullptr, nullptr), -ENOENT);
    EXPECT_EQ(std::string(chm_program_error()), "/no/such/program.so: No such file or directory");
    EXPECT_EQ(chm_program_load(NOMAIN_PATH, 0, nullptr, nullptr, nullptr), -ENOEXEC);
    EXPECT_EQ(std::string(chm_program_error()).rfind(std::string(NOMAIN_PATH) + ": no main", 0), 0u)
        << chm_program_error();
    EXPECT_NE(std::string(chm_program_error()).find("int main(int argc, char** argv)"), std::string::npos)
        << chm_program_error();
    // Linked against libchimera: refused before dlopen could load a
    // second copy of the library, saying how to build it instead.
    EXPECT_EQ(chm_program_load(LINKED_PATH, 0, nullptr, nullptr, nullptr), -ENOEXEC);
    const std::string linked = chm_program_error();
    EXPECT_EQ(linked.rfind(std::string(LINKED_PATH) + ": linked against libchimera.so", 0), 0u) << linked;
    EXPECT_NE(linked.find("pkg-config --cflags chimera"), std::string::npos) << linked;
    // A file that is not a shared object at all: this test's own source.
    EXPECT_EQ(chm_program_load(SOURCE_PATH, 0, nullptr, nullptr, nullptr), -ENOEXEC);
    {
        const std::string e = chm_program_error();
        EXPECT_EQ(e.find(SOURCE_PATH), 0u) << e;
        EXPECT_EQ(e.find(SOURCE_PATH, 1), std::string::npos) << "the file named twice: " << e;
    }
    EXPECT_EQ(chm_program_load(nullptr, 0, nullptr, nullptr, nullptr), -EINVAL);
    EXPECT_EQ(chm_program_load(CTLPROG_PATH, 2, nullptr, nullptr, nullptr), -EINVAL);
    EXPECT_EQ(chm_task_count(), 0);
    EXPECT_EQ(chm_program_status(0, nullptr), -EINVAL);
}

TEST(ProgramNoKernel, LoadingNeedsAKernel) {
    EXPECT_EQ(chm_program_load(CTLPROG_PATH, 0, nullptr, nullptr, nullptr), -EPERM);
}

}  // namespace
}  // namespace chm::test
