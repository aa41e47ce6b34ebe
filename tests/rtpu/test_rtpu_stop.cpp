// A graceful stop leaves no stale waiters (issue 15, item 2): an RTPU
// stopped by SIGTERM or by an express-mail stop while a task of it is
// parked in a backplane wait (queue send and receive, remote-semaphore P,
// an express-mail request) withdraws that task's record before it leaves.
// Afterwards chimera-bpcheck is clean, the object serves the next user,
// and no message or unit is lost or duplicated: one granted to the
// departing waiter goes to the next waiter or back to the object.
#include <atomic>
#include <thread>

#include "chimera/msgq.h"
#include "chimera/rsem.h"
#include "chimera/shm.h"
#include "ipc/backplane/backplane.hpp"
#include "ipc/xmail/xmail.hpp"
#include "rtpu_fixture.hpp"

using namespace chm::test;

namespace {

enum class Wait { Send, Recv, P, Mail };
enum class Stop { Sigterm, ExpressMail };

struct Case {
    Wait wait;
    Stop stop;
    bool granted;  // the waiter is granted (message / unit) while its RTPU is frozen, then stopped
    const char* name;
};

const char* kind_arg(Wait w) {
    switch (w) {
    case Wait::Send: return "send";
    case Wait::Recv: return "recv";
    case Wait::P: return "p";
    default: return "mail";
    }
}

// Requests `token` has in `rtpu`'s ring that are not FREE.
int records_of(int rtpu, std::uint32_t token) {
    const chm::bp::View& v = *chm::bp::current();
    chm::bp::RingHeader* ring = v.ring(std::uint32_t(rtpu));
    int n = 0;
    for (std::uint32_t i = 0; i < chm::xmail::ring_capacity(v); ++i) {
        chm::xmail::Record* r = chm::xmail::record_at(v, ring, i);
        if (chm::xmail::phase_of(r->state.load()) != chm::xmail::kFree && r->owner.load() == token) ++n;
    }
    return n;
}

bool poll_until(const std::function<bool()>& cond, int timeout_ms = 10000) {
    const std::uint64_t end = now_ms() + std::uint64_t(timeout_ms);
    while (!cond()) {
        if (now_ms() > end) return false;
        nap_ms(2);
    }
    return true;
}

class StopTest : public RtpuTest, public ::testing::WithParamInterface<Case> {
protected:
    void TearDown() override {
        if (helper_.joinable()) helper_.join();  // bounded: its own call has a timeout
        RtpuTest::TearDown();
    }
    chm_msgq_info_t info() {
        chm_msgq_info_t st{};
        EXPECT_EQ(chm_msgq_info(q_, &st), 0);
        return st;
    }
    int waiting() {
        if (s_) return chm_rsem_waiting(s_);
        const chm_msgq_info_t st = info();
        return int(st.senders_waiting + st.receivers_waiting);
    }
    chm_msgq_t* q_ = nullptr;
    chm_rsem_t* s_ = nullptr;
    std::thread helper_;
};

TEST_P(StopTest, ParkedWaiterWithdrawnAndNothingLost) {
    const Case c = GetParam();
    create();
    pid_t target = -1;
    if (c.wait == Wait::Send || c.wait == Wait::Recv) {
        chm_msgq_attr_t a;
        chm_msgq_attr_init(&a);
        a.max_msg = 32;
        a.max_count = 1;
        ASSERT_EQ(chm_msgq_create("q", &a, CHM_MSGQ_COMMON, &q_), 0) << chm_bp_last_error();
        if (c.wait == Wait::Send) {
            ASSERT_EQ(chm_msgq_try_send(q_, 1, 0, "first", 6), 0);
        }
    } else if (c.wait == Wait::P) {
        ASSERT_EQ(chm_rsem_create("s", CHM_SEM_COUNTING, 0, CHM_SHM_COMMON, &s_), 0) << chm_bp_last_error();
    } else {
        // The request's target: an RTPU whose process is frozen, so the
        // request stays posted and its sender parked.
        target = start_rtpu(2);
        ASSERT_TRUE(wait_serving(2, target)) << read_file(err_of(2));
        ASSERT_EQ(kill(target, SIGSTOP), 0);
    }
    const std::string notes = dir_ + "/notes";
    const pid_t p = start_rtpu(1, {BLOCKER_SO, notes, kind_arg(c.wait), c.wait == Wait::Mail ? "2" : c.wait == Wait::P ? "s" : "q"});
    ASSERT_TRUE(wait_serving(1, p)) << read_file(err_of(1));
    ASSERT_TRUE(wait_text(notes, "waiting")) << read_file(notes) << read_file(err_of(1));
    chm_bp_status_t st;
    ASSERT_EQ(chm_bp_status(&st), 0);
    const std::uint32_t token = chm::bp::make_token(1, st.slot[1].generation);
    if (c.wait == Wait::Mail) {
        ASSERT_TRUE(poll_until([&] { return records_of(2, token) == 1; })) << "the request was never posted";
    } else {
        ASSERT_TRUE(poll_until([&] { return waiting() == 1; })) << "the task never parked";
    }

    // Granted variants: a host thread waits behind the task; the task's
    // record is granted while its RTPU is frozen (SIGSTOP), so it cannot
    // take what it was given before the stop.
    std::atomic<int> helper_result{1};
    char helper_buf[32] = {0};
    if (c.granted) {
        helper_ = std::thread([&] {
            helper_result = s_ ? chm_rsem_p_timed(s_, 5'000'000'000)
                               : chm_msgq_receive_timed(q_, helper_buf, sizeof helper_buf, nullptr, 5'000'000'000);
        });
        ASSERT_TRUE(poll_until([&] { return waiting() == 2; })) << "the host thread never parked";
        ASSERT_EQ(kill(p, SIGSTOP), 0);
    }

    if (c.stop == Stop::Sigterm) {
        ASSERT_FALSE(c.granted) << "see below: the granted cases stop by express mail";
        ASSERT_EQ(kill(p, SIGTERM), 0);
    } else if (!c.granted) {
        ASSERT_EQ(chm_rtpu_stop(1, 0), 0) << chm_rtpu_last_error();
    } else {
        // The stop request is posted before the grant, so when the RTPU
        // thaws its express-mail server (priority 1000) stops the kernel
        // before the granted task (the program's, below it) can run: the
        // grant is left to the withdrawal. (A SIGTERM is read from a
        // descriptor after the grant's vector, and the task ran first.)
        std::atomic<int> stopped{1};
        std::thread stopper([&] { stopped = chm_rtpu_stop(1, 0); });
        const std::uint32_t me = chm::bp::make_token(std::uint32_t(chm_bp_self()), st.slot[chm_bp_self()].generation);
        const bool posted = poll_until([&] { return records_of(1, me) == 1; }, 5000);
        if (s_) {
            EXPECT_EQ(chm_rsem_v(s_), 0);
        } else {
            EXPECT_EQ(chm_msgq_try_send(q_, 1, 0, "m", 2), 0);
        }
        kill(p, SIGCONT);
        stopper.join();
        ASSERT_TRUE(posted) << "the stop request was never posted";
        ASSERT_EQ(stopped.load(), 0) << chm_rtpu_last_error();
    }
    ASSERT_EQ(reap(p), 0) << read_file(err_of(1));
    ASSERT_TRUE(wait_slot(1, CHM_BP_FREE));
    if (helper_.joinable()) helper_.join();
    const std::string said = read_file(notes);

    // Nothing stale: the checker, and (express mail) the target's ring.
    if (c.wait == Wait::Mail) {
        EXPECT_EQ(records_of(2, token), 0) << "the departed sender's request is still in RTPU 2's ring";
    }
    const Outcome chk = run({CHIMERA_BPCHECK_BIN, bp_});
    EXPECT_EQ(chk.status, 0) << chk.out << chk.err;

    // The object serves the next user; every message and unit is accounted for.
    switch (c.wait) {
    case Wait::Send: {
        EXPECT_EQ(said.find("sent"), std::string::npos) << said;
        const chm_msgq_info_t i = info();
        EXPECT_EQ(i.count, 1u);
        EXPECT_EQ(i.senders_waiting, 0u);
        char buf[32] = {0};
        ASSERT_EQ(chm_msgq_try_receive(q_, buf, sizeof buf, nullptr), 6);
        EXPECT_STREQ(buf, "first");
        EXPECT_EQ(chm_msgq_try_send(q_, 1, 0, "next", 5), 0);
        EXPECT_EQ(chm_msgq_try_receive(q_, buf, sizeof buf, nullptr), 5);
        break;
    }
    case Wait::Recv: {
        const chm_msgq_info_t i = info();
        EXPECT_EQ(i.receivers_waiting, 0u);
        if (c.granted) {
            // "m" went to exactly one receiver: the task (had it run
            // before the stop) or, passed on, the host thread.
            const bool task_got = said.find("got m") != std::string::npos;
            const bool helper_got = helper_result == 2 && !std::strcmp(helper_buf, "m");
            EXPECT_NE(task_got, helper_got) << said << "helper: " << helper_result;
            EXPECT_EQ(i.count, 0u);
        } else {
            EXPECT_EQ(i.count, 0u);
        }
        char buf[32] = {0};
        EXPECT_EQ(chm_msgq_try_send(q_, 1, 0, "next", 5), 0);
        EXPECT_EQ(chm_msgq_try_receive(q_, buf, sizeof buf, nullptr), 5);
        break;
    }
    case Wait::P: {
        EXPECT_EQ(chm_rsem_waiting(s_), 0);
        if (c.granted) {
            const bool task_got = said.find("got unit") != std::string::npos;
            const bool helper_got = helper_result == 0;
            EXPECT_NE(task_got, helper_got) << said << "helper: " << helper_result;
        }
        EXPECT_EQ(chm_rsem_value(s_), 0);
        EXPECT_EQ(chm_rsem_v(s_), 0);
        EXPECT_EQ(chm_rsem_try_p(s_), 0);
        break;
    }
    case Wait::Mail:
        ASSERT_EQ(kill(target, SIGCONT), 0);
        EXPECT_EQ(chm_rtpu_ping(2, nullptr), 0) << chm_rtpu_last_error();
        break;
    }
}

INSTANTIATE_TEST_SUITE_P(
    EveryWait, StopTest,
    ::testing::Values(Case{Wait::Send, Stop::Sigterm, false, "SendSigterm"},
                      Case{Wait::Send, Stop::ExpressMail, false, "SendExpressMail"},
                      Case{Wait::Recv, Stop::Sigterm, false, "ReceiveSigterm"},
                      Case{Wait::Recv, Stop::ExpressMail, false, "ReceiveExpressMail"},
                      Case{Wait::Recv, Stop::ExpressMail, true, "ReceiveGrantedExpressMail"},
                      Case{Wait::P, Stop::Sigterm, false, "PSigterm"},
                      Case{Wait::P, Stop::ExpressMail, false, "PExpressMail"},
                      Case{Wait::P, Stop::ExpressMail, true, "PGrantedExpressMail"},
                      Case{Wait::Mail, Stop::Sigterm, false, "MailSigterm"},
                      Case{Wait::Mail, Stop::ExpressMail, false, "MailExpressMail"}),
    [](const ::testing::TestParamInfo<Case>& i) { return std::string(i.param.name); });

}  // namespace
