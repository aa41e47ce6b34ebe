// A remote semaphore's repair after a granter ended between marking a
// waiter's record GRANTED and storing its grant word (fault and stop point
// rsem.v.granted): the checker's view of that half-done grant, and the
// recovery that finishes it. The kill and in-task matrices of
// test_ipc_fault.cpp run the same point; this test holds the state still
// so that the checker can look at it. Every wait is bounded.
#include <cerrno>
#include <string>

#include "chimera/rsem.h"
#include "ipc_fixture.hpp"
#include "rsem_fixture.hpp"

namespace chm::test {
namespace {

constexpr std::uint64_t kWaiterTimeoutNs = 30'000'000'000ull;  // only a lost grant takes this long

class RsemRepair : public RsemTest {};

// A host process waits in P; another process's V stops at rsem.v.granted
// and is killed there while the waiter's process is itself stopped, so
// nobody has recovered yet. chimera-bpcheck reports the dead holder of the
// dirty lock but not the half-done grant, which the repair finishes. Let
// go, the waiter's own monitor recovers the dead slot, and its P returns
// the unit. Without the repair it timed out (-ETIMEDOUT) and the unit was
// lost.
TEST_F(RsemRepair, AGrantLeftHalfDoneByAKilledVIsFinishedByTheRecovery) {
    create();
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), "test", nullptr), 0) << chm_bp_last_error();
    chm_rsem_t* s = make("s");
    ASSERT_NE(s, nullptr);
    const std::string path = path_;
    const pid_t waiter = spawn([path] {
        if (chm_bp_attach_host(path.c_str(), "waiter", nullptr) != 0) return 90;
        chm_rsem_t* mine = open_sem("s");
        if (!mine) return 91;
        const int r = chm_rsem_p_timed(mine, kWaiterTimeoutNs);
        (void)chm_bp_leave();
        return r == 0 ? 0 : r == -ETIMEDOUT ? 92 : 93;
    });
    ASSERT_TRUE(until_waiting(s, 1));
    // Nobody attached may run the recovery until the checker has looked.
    ASSERT_EQ(chm_bp_leave(), 0);
    kill(waiter, SIGSTOP);
    ASSERT_TRUE(wait_stopped(waiter));
    const pid_t granter = spawn([path] {
        if (chm_bp_attach_host(path.c_str(), "granter", nullptr) != 0) return 90;
        chm_rsem_t* mine = open_sem("s");
        if (!mine) return 91;
        stop_at("rsem.v.granted");
        (void)chm_rsem_v(mine);
        return 92;  // the stop point did not stop it
    });
    ASSERT_TRUE(wait_stopped(granter));
    kill9(granter);

    std::string out;
    EXPECT_EQ(bpcheck(path_, &out), 1) << out;
    EXPECT_NE(out.find("held by a dead owner"), std::string::npos) << out;
    EXPECT_EQ(out.find("GRANTED"), std::string::npos) << "a half-done grant on a dirty lock is the repair's:\n"
                                                       << out;

    kill(waiter, SIGCONT);
    EXPECT_EQ(reap(waiter, 60000), 0) << "92: the waiter's P timed out, the unit lost";
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), "test", nullptr), 0) << chm_bp_last_error();
    EXPECT_EQ(chm_rsem_value(s), 0) << "the unit went to the waiter, not to the count";
    EXPECT_EQ(chm_rsem_waiting(s), 0);
    EXPECT_EQ(check_now(), "");
    EXPECT_EQ(bpcheck(path_, &out), 0) << out;
}

}  // namespace
}  // namespace chm::test
