// chm_err_last: one call gives the text of the calling task's last error,
// whatever subsystem raised it. Per task on one RTPU (the virtual clock
// interleaves two failing tasks), per thread outside tasks; a failure with
// nothing to say never shows an older message; each subsystem's message
// reaches it; chm_err_set_last for libraries built on Chimera.
#include <gtest/gtest.h>

#include <cerrno>
#include <fcntl.h>
#include <string>
#include <thread>

#include "chimera/chimera.h"
#include "../kernel/kernel_fixture.hpp"

namespace chm::test {
namespace {

using LastError = KernelTest;

std::string g_a, g_b;

// Task a fails a kernel call, lets b run (b fails differently), then reads.
void task_a(void*) {
    EXPECT_EQ(chm_sem_p(nullptr), -EINVAL);
    chm_task_yield();
    g_a = chm_err_last();
}
void task_b(void*) {
    EXPECT_EQ(chm_unix_open("/nonexistent-chimera/file", O_RDONLY), -1);
    chm_task_yield();
    g_b = chm_err_last();
}

TEST_F(LastError, EachTaskReadsItsOwn) {
    start(CHM_SCHED_FIXED);
    spawn(task_a, nullptr, "a", 5);
    spawn(task_b, nullptr, "b", 5);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_a, "chm_sem_p: Invalid argument");
    EXPECT_EQ(g_b, "open /nonexistent-chimera/file: No such file or directory");
}

// A subsystem's message, then a failure with nothing to say: the second
// call's own text, never the first's.
void stale(void*) {
    chm_msgq_t* q = nullptr;
    EXPECT_EQ(chm_msgq_open("loop.sense", &q), -ENOTCONN);
    g_a = chm_err_last();
    chm_tid_t t;
    EXPECT_EQ(chm_task_find("no such task", &t), -ESRCH);
    g_b = chm_err_last();
}

TEST_F(LastError, AFailureWithoutAMessageDoesNotShowAnOlderOne) {
    start(CHM_SCHED_FIXED);
    spawn(stale, nullptr, "s", 5);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_NE(g_a.find("not attached"), std::string::npos) << g_a;
    EXPECT_EQ(g_b.find("not attached"), std::string::npos) << g_b;
    EXPECT_NE(g_b.find("chm_task_find"), std::string::npos) << g_b;
}

// The other subsystems, outside a task (a host thread), each naming what
// was wrong.
TEST(LastErrorThread, EverySubsystemLeavesItsMessage) {
    chm_config_t* c = nullptr;
    EXPECT_EQ(chm_config_open("/nonexistent-chimera/app.toml", &c), -ENOENT);
    EXPECT_NE(std::string(chm_err_last()).find("/nonexistent-chimera/app.toml"), std::string::npos) << chm_err_last();

    chm_err_set_last("%s %d", "set by a library", 42);
    EXPECT_STREQ(chm_err_last(), "set by a library 42");

    ASSERT_NE(chm_bp_attach_host("/nonexistent-chimera/x.bp", "t", nullptr), 0);
    EXPECT_NE(std::string(chm_err_last()).find("/nonexistent-chimera/x.bp"), std::string::npos) << chm_err_last();

    chm_msgq_t* q = nullptr;
    EXPECT_LT(chm_msgq_open("q", &q), 0);
    EXPECT_NE(std::string(chm_err_last()).find("not attached"), std::string::npos) << chm_err_last();

    double a[4] = {}, b[6] = {}, out[4] = {};
    const chm_mat_t A = {a, 2, 2, 2}, B = {b, 3, 2, 2}, O = {out, 2, 2, 2};
    EXPECT_LT(chm_mat_mul(&A, &B, &O), 0);
    EXPECT_NE(std::string(chm_err_last()).find("chm_mat_mul"), std::string::npos) << chm_err_last();

    EXPECT_LT(chm_dev_open("no-such-device", 0), 0);
    EXPECT_NE(std::string(chm_err_last()).find("no-such-device"), std::string::npos) << chm_err_last();

    // Another thread has its own.
    std::string other;
    std::thread([&] {
        other = chm_err_last();
        chm_err_set_last("the other thread's");
    }).join();
    EXPECT_EQ(other, "");
    EXPECT_NE(std::string(chm_err_last()).find("no-such-device"), std::string::npos) << chm_err_last();

    // The old names still work, and leave the text too.
    EXPECT_EQ(chm_open("/nonexistent-chimera/old", O_RDONLY), -1);
    EXPECT_STREQ(chm_err_last(), "open /nonexistent-chimera/old: No such file or directory");
}

}  // namespace
}  // namespace chm::test
