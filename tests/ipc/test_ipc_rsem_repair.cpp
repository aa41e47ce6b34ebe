// A remote semaphore's repair after a granter ended between marking a
// waiter's record GRANTED and storing its grant word (fault and stop point
// rsem.v.granted): the checker's view of that half-done grant, and the
// recovery that finishes it. The kill and in-task matrices of
// test_ipc_fault.cpp run the same point; this test holds the state still
// so that the checker can look at it. Every wait is bounded.
#include <cerrno>
#include <string>

#include "chimera/rsem.h"
#include "ipc/rsem/rsem.hpp"
#include "ipc_fixture.hpp"
#include "rsem_fixture.hpp"

namespace chm::test {
namespace {

constexpr std::uint64_t kWaiterTimeoutNs = 30'000'000'000ull;  // only a lost grant takes this long

// A host process waits in P; another process's V stops at rsem.v.granted
// and is killed there while the waiter's process is itself stopped, so
// nobody has recovered yet. chimera-bpcheck reports the dead holder of the
// dirty lock but not the half-done grant, which the repair finishes.
// Returns the waiter's pid (still stopped); this process is left detached.
class RsemRepair : public RsemTest {
protected:
    pid_t half_done_grant() {
        create();
        EXPECT_EQ(chm_bp_attach_host(path_.c_str(), "test", nullptr), 0) << chm_bp_last_error();
        chm_rsem_t* s = make("s");
        EXPECT_NE(s, nullptr);
        const std::string path = path_;
        const pid_t waiter = spawn([path] {
            if (chm_bp_attach_host(path.c_str(), "waiter", nullptr) != 0) return 90;
            chm_rsem_t* mine = open_sem("s");
            if (!mine) return 91;
            const int r = chm_rsem_p_timed(mine, kWaiterTimeoutNs);
            (void)chm_bp_leave();
            return r == 0 ? 0 : r == -ETIMEDOUT ? 92 : 93;
        });
        EXPECT_TRUE(until_waiting(s, 1));
        // Nobody attached may run the recovery until the checker has looked.
        EXPECT_EQ(chm_bp_leave(), 0);
        kill(waiter, SIGSTOP);
        EXPECT_TRUE(wait_stopped(waiter));
        const pid_t granter = spawn([path] {
            if (chm_bp_attach_host(path.c_str(), "granter", nullptr) != 0) return 90;
            chm_rsem_t* mine = open_sem("s");
            if (!mine) return 91;
            stop_at("rsem.v.granted");
            (void)chm_rsem_v(mine);
            return 92;  // the stop point did not stop it
        });
        EXPECT_TRUE(wait_stopped(granter));
        kill9(granter);

        std::string out;
        EXPECT_EQ(bpcheck(path_, &out), 1) << out;
        EXPECT_NE(out.find("held by a dead owner"), std::string::npos) << out;
        EXPECT_EQ(out.find("GRANTED"), std::string::npos) << "a half-done grant on a dirty lock is the repair's:\n"
                                                           << out;
        return waiter;
    }
    // Attached again: nobody waits, the count is `units`, the file checks clean.
    void expect_settled(int units) {
        ASSERT_EQ(chm_bp_attach_host(path_.c_str(), "test", nullptr), 0) << chm_bp_last_error();
        chm_rsem_t* s = open_sem("s");
        ASSERT_NE(s, nullptr);
        // Every dead slot recovered (by this attach's monitor, if not before).
        const std::uint64_t end = now_ns() + 20'000'000'000ull;
        while ((check_now() != "" || chm_rsem_value(s) != units) && now_ns() < end) sleep_us(1000);
        EXPECT_EQ(chm_rsem_value(s), units);
        EXPECT_EQ(chm_rsem_waiting(s), 0);
        EXPECT_EQ(check_now(), "");
        std::string out;
        EXPECT_EQ(bpcheck(path_, &out), 0) << out;
    }
};

// Let go, the waiter's own monitor recovers the dead granter's slot, and
// its P returns the unit. Without the repair it timed out (-ETIMEDOUT)
// and the unit was lost.
TEST_F(RsemRepair, AGrantLeftHalfDoneByAKilledVIsFinishedByTheRecovery) {
    const pid_t waiter = half_done_grant();
    kill(waiter, SIGCONT);
    EXPECT_EQ(reap(waiter, 60000), 0) << "92: the waiter's P timed out, the unit lost";
    expect_settled(0);  // the unit went to the waiter, not to the count
}

// The waiter is killed too: the unit goes back to the count (whichever
// recovery runs first: the granter's repair, or the waiter's, which passes
// on a grant its dead slot never took).
TEST_F(RsemRepair, AHalfDoneGrantToAWaiterThatDiedToo) {
    const pid_t waiter = half_done_grant();
    kill(waiter, SIGKILL);
    EXPECT_EQ(reap(waiter), -SIGKILL);
    expect_settled(1);
}

// The same record on a lock that is free and clean is damage: no repair
// will come to finish that grant, and the checker says so.
TEST_F(RsemRepair, AHalfDoneGrantOnACleanLockIsDamage) {
    create();
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), "test", nullptr), 0) << chm_bp_last_error();
    chm_rsem_t* h = make("s");
    ASSERT_NE(h, nullptr);
    ipc::rsem::Rsem* s = ipc::rsem::rsem_at(h);
    ipc::rsem::Waiter& w = s->w[3];
    w.owner.store(bp::current()->token);
    __atomic_store_n(ipc::rsem::grant_of(s, &w), 0u, __ATOMIC_RELEASE);
    w.state.store(ipc::rsem::kGranted);
    const std::string out = check_now();
    EXPECT_NE(out.find("waiter 3 (and 0 more) is GRANTED but its grant word was never stored"), std::string::npos)
        << out;
    __atomic_store_n(ipc::rsem::grant_of(s, &w), 1u, __ATOMIC_RELEASE);  // stored: a grant not yet taken
    EXPECT_EQ(check_now(), "");
    w.state.store(ipc::rsem::kFree);
}

}  // namespace
}  // namespace chm::test
