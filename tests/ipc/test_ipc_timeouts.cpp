// The timeout convention (chimera/kernel.h, "Timeouts") on the backplane
// calls: remote semaphores and message queues. Tasks of one RTPU (a forked
// child) on the virtual clock, where every wait is exact: CHM_NO_WAIT fails
// at once with -EAGAIN, a positive timeout and an _until deadline end with
// -ETIMEDOUT exactly then, a deadline already past does not wait,
// CHM_FOREVER and a -1 from a caller of the old int64_t signature wait for
// the peer. Then a host thread, on CLOCK_MONOTONIC (bounds only).
#include <cerrno>
#include <cstdio>

#include "chimera/chimera.h"
#include "chimera/msgq.h"
#include "chimera/rsem.h"
#include "msgq_fixture.hpp"
#include "rsem_fixture.hpp"
#include "rtpu_child.hpp"

namespace chm::test {
namespace {

constexpr std::uint64_t kMs = 1'000'000;
const std::int64_t kOldForever = -1;  // what int64_t callers passed for "no limit"

int g_fail = 0;  // failed checks in the child

#define CHILD_EQ(a, b)                                                                                   \
    do {                                                                                                 \
        const long long va_ = (long long)(a), vb_ = (long long)(b);                                      \
        if (va_ != vb_) {                                                                                \
            ++g_fail;                                                                                    \
            std::fprintf(stderr, "%s:%d: %s is %lld, expected %lld (t=%llu)\n", __FILE__, __LINE__, #a, \
                         va_, vb_, (unsigned long long)chm_time_now());                                  \
        }                                                                                                \
    } while (0)

// The peer: at each of these instants, one `act` (a V, a send, a receive).
struct Peer {
    std::uint64_t at[4];
    int n;
    int (*act)();
};
Peer g_peer;

void peer_task(void*) {
    for (int i = 0; i < g_peer.n; ++i) {
        chm_task_pause_until(g_peer.at[i]);
        CHILD_EQ(g_peer.act(), 0);
    }
}

// Runs `body` (priority 2) and the peer (priority 1) on an RTPU in slot 1
// on the virtual clock, after `setup` (joined, kernel ready): the child's
// exit status, 0 when every check held.
int run_virtual(const std::string& path, void (*body)(void*), bool (*setup)()) {
    RtpuOptions o;
    o.virtual_clock = 1;
    const int r = run_rtpu(path, 1, [body, setup] {
        return setup() && spawn_task(body, nullptr, "body", 2) != CHM_TID_NONE &&
               spawn_task(peer_task, nullptr, "peer", 1) != CHM_TID_NONE;
    }, o);
    return r ? r : (g_fail ? 50 : 0);
}

// ------------------------------------------------------------ rsem

chm_rsem_t* g_sem = nullptr;

void rsem_body(void*) {
    chm_rsem_t* s = open_sem("sem");
    if (!s) return (void)++g_fail;
    const std::uint64_t t0 = chm_time_now();
    CHILD_EQ(chm_rsem_p_timed(s, CHM_NO_WAIT), -EAGAIN);
    CHILD_EQ(chm_time_now(), t0);
    CHILD_EQ(chm_rsem_p_timed(s, 5 * kMs), -ETIMEDOUT);
    CHILD_EQ(chm_time_now(), t0 + 5 * kMs);
    CHILD_EQ(chm_rsem_p_until(s, t0 + 12 * kMs), -ETIMEDOUT);
    CHILD_EQ(chm_time_now(), t0 + 12 * kMs);
    CHILD_EQ(chm_rsem_p_until(s, t0 + 11 * kMs), -ETIMEDOUT);  // past
    CHILD_EQ(chm_rsem_p_until(s, t0 + 12 * kMs), -ETIMEDOUT);  // now
    CHILD_EQ(chm_time_now(), t0 + 12 * kMs);
    // The peer gives at 20, 30, 40 and 50 ms.
    CHILD_EQ(chm_rsem_p_timed(s, CHM_FOREVER), 0);
    CHILD_EQ(chm_time_now(), t0 + 20 * kMs);
    CHILD_EQ(chm_rsem_p_timed(s, kOldForever), 0);
    CHILD_EQ(chm_time_now(), t0 + 30 * kMs);
    CHILD_EQ(chm_rsem_p_until(s, CHM_FOREVER), 0);
    CHILD_EQ(chm_time_now(), t0 + 40 * kMs);
    CHILD_EQ(chm_rsem_p_until(s, t0 + 100 * kMs), 0);
    CHILD_EQ(chm_time_now(), t0 + 50 * kMs);
    CHILD_EQ(chm_rsem_v(s), 0);
    CHILD_EQ(chm_rsem_p_until(s, t0), 0);  // past, but free: taken
    CHILD_EQ(chm_time_now(), t0 + 50 * kMs);
}

class Timeouts : public RsemTest {
protected:
    void SetUp() override {
        IpcTest::SetUp();
        create();
        ASSERT_EQ(chm_bp_attach_host(path_.c_str(), "test", nullptr), 0) << chm_bp_last_error();
    }
};

TEST_F(Timeouts, RsemOnTheVirtualClock) {
    ASSERT_NE(make("sem"), nullptr);
    const std::string path = path_;
    const pid_t child = spawn([path] {
        g_peer = Peer{{20 * kMs, 30 * kMs, 40 * kMs, 50 * kMs}, 4, [] { return chm_rsem_v(g_sem); }};
        return run_virtual(path, rsem_body, [] { return (g_sem = open_sem("sem")) != nullptr; });
    });
    EXPECT_EQ(reap(child), 0) << "50: a check failed (see its stderr)";
}

// ------------------------------------------------------------ msgq

chm_msgq_t* g_q = nullptr;

int send_one() { return chm_msgq_try_send(g_q, 1, 0, "m", 1); }
int take_one() {
    char b[16];
    return chm_msgq_try_receive(g_q, b, sizeof b, nullptr) == 1 ? 0 : -1;
}

void msgq_receive_body(void*) {
    char b[16];
    const std::uint64_t t0 = chm_time_now();
    CHILD_EQ(chm_msgq_receive_timed(g_q, b, sizeof b, nullptr, CHM_NO_WAIT), -EAGAIN);
    CHILD_EQ(chm_time_now(), t0);
    CHILD_EQ(chm_msgq_receive_timed(g_q, b, sizeof b, nullptr, 5 * kMs), -ETIMEDOUT);
    CHILD_EQ(chm_time_now(), t0 + 5 * kMs);
    CHILD_EQ(chm_msgq_receive_until(g_q, b, sizeof b, nullptr, t0 + 12 * kMs), -ETIMEDOUT);
    CHILD_EQ(chm_time_now(), t0 + 12 * kMs);
    CHILD_EQ(chm_msgq_receive_until(g_q, b, sizeof b, nullptr, t0 + 11 * kMs), -ETIMEDOUT);
    CHILD_EQ(chm_msgq_receive_until(g_q, b, sizeof b, nullptr, t0 + 12 * kMs), -ETIMEDOUT);
    CHILD_EQ(chm_time_now(), t0 + 12 * kMs);
    // The peer sends at 20, 30, 40 and 50 ms.
    CHILD_EQ(chm_msgq_receive_timed(g_q, b, sizeof b, nullptr, CHM_FOREVER), 1);
    CHILD_EQ(chm_time_now(), t0 + 20 * kMs);
    CHILD_EQ(chm_msgq_receive_timed(g_q, b, sizeof b, nullptr, kOldForever), 1);
    CHILD_EQ(chm_time_now(), t0 + 30 * kMs);
    CHILD_EQ(chm_msgq_receive_until(g_q, b, sizeof b, nullptr, CHM_FOREVER), 1);
    CHILD_EQ(chm_time_now(), t0 + 40 * kMs);
    CHILD_EQ(chm_msgq_receive_until(g_q, b, sizeof b, nullptr, t0 + 100 * kMs), 1);
    CHILD_EQ(chm_time_now(), t0 + 50 * kMs);
    CHILD_EQ(send_one(), 0);
    CHILD_EQ(chm_msgq_receive_until(g_q, b, sizeof b, nullptr, t0), 1);  // past, but there: taken
    CHILD_EQ(chm_time_now(), t0 + 50 * kMs);
}

void msgq_send_body(void*) {
    const std::uint64_t t0 = chm_time_now();
    CHILD_EQ(send_one(), 0);  // the queue holds one message: full
    CHILD_EQ(chm_msgq_send_timed(g_q, 1, 0, "m", 1, CHM_NO_WAIT), -EAGAIN);
    CHILD_EQ(chm_time_now(), t0);
    CHILD_EQ(chm_msgq_send_timed(g_q, 1, 0, "m", 1, 5 * kMs), -ETIMEDOUT);
    CHILD_EQ(chm_time_now(), t0 + 5 * kMs);
    CHILD_EQ(chm_msgq_send_until(g_q, 1, 0, "m", 1, t0 + 12 * kMs), -ETIMEDOUT);
    CHILD_EQ(chm_time_now(), t0 + 12 * kMs);
    CHILD_EQ(chm_msgq_send_until(g_q, 1, 0, "m", 1, t0 + 11 * kMs), -ETIMEDOUT);
    CHILD_EQ(chm_msgq_send_until(g_q, 1, 0, "m", 1, t0 + 12 * kMs), -ETIMEDOUT);
    CHILD_EQ(chm_time_now(), t0 + 12 * kMs);
    // The peer takes one at 20, 30, 40 and 50 ms.
    CHILD_EQ(chm_msgq_send_timed(g_q, 1, 0, "m", 1, CHM_FOREVER), 0);
    CHILD_EQ(chm_time_now(), t0 + 20 * kMs);
    CHILD_EQ(chm_msgq_send_timed(g_q, 1, 0, "m", 1, kOldForever), 0);
    CHILD_EQ(chm_time_now(), t0 + 30 * kMs);
    CHILD_EQ(chm_msgq_send_until(g_q, 1, 0, "m", 1, CHM_FOREVER), 0);
    CHILD_EQ(chm_time_now(), t0 + 40 * kMs);
    CHILD_EQ(chm_msgq_send_until(g_q, 1, 0, "m", 1, t0 + 100 * kMs), 0);
    CHILD_EQ(chm_time_now(), t0 + 50 * kMs);
    CHILD_EQ(take_one(), 0);
    CHILD_EQ(chm_msgq_send_until(g_q, 1, 0, "m", 1, t0), 0);  // past, but room: sent
    CHILD_EQ(chm_time_now(), t0 + 50 * kMs);
}

class MsgqTimeouts : public MsgqTest {
protected:
    pid_t spawn_child(void (*body)(void*), int (*act)()) {
        const std::string path = path_;
        return spawn([path, body, act] {
            g_peer = Peer{{20 * kMs, 30 * kMs, 40 * kMs, 50 * kMs}, 4, act};
            return run_virtual(path, body, [] { return chm_msgq_open("q", &g_q) == 0; });
        });
    }
    void SetUp() override {
        IpcTest::SetUp();
        create();
        ASSERT_EQ(chm_bp_attach_host(path_.c_str(), "test", nullptr), 0) << chm_bp_last_error();
        ASSERT_NE(make_queue("q", CHM_MSGQ_FIFO, 16, 1), nullptr);
    }
};

TEST_F(MsgqTimeouts, ReceiveOnTheVirtualClock) {
    EXPECT_EQ(reap(spawn_child(msgq_receive_body, send_one)), 0)
        << "50: a check failed (see its stderr)";
}

TEST_F(MsgqTimeouts, SendOnTheVirtualClock) {
    EXPECT_EQ(reap(spawn_child(msgq_send_body, take_one)), 0)
        << "50: a check failed (see its stderr)";
}

// ------------------------------------------------------------ host thread

// A host thread waits on CLOCK_MONOTONIC, which is chm_time_now()'s clock
// in a process without a virtual-clock kernel: bounds, not exact values.
TEST_F(MsgqTimeouts, AHostThreadWaitsUntilItsDeadline) {
    chm_msgq_t* q = nullptr;
    ASSERT_EQ(chm_msgq_open("q", &q), 0);
    chm_rsem_t* s = nullptr;
    ASSERT_EQ(chm_rsem_create("sem", CHM_SEM_BINARY, 0, CHM_SHM_COMMON, &s), 0) << chm_bp_last_error();
    char b[16];
    std::uint64_t t0 = chm_time_now();
    EXPECT_EQ(chm_rsem_p_until(s, t0 - 1), -ETIMEDOUT);
    EXPECT_EQ(chm_msgq_receive_until(q, b, sizeof b, nullptr, t0 - 1), -ETIMEDOUT);
    EXPECT_EQ(chm_rsem_p_timed(s, CHM_NO_WAIT), -EAGAIN);
    EXPECT_EQ(chm_msgq_receive_timed(q, b, sizeof b, nullptr, CHM_NO_WAIT), -EAGAIN);
    EXPECT_LT(chm_time_now() - t0, 1000 * kMs) << "none of these waited";
    t0 = chm_time_now();
    EXPECT_EQ(chm_rsem_p_until(s, t0 + 30 * kMs), -ETIMEDOUT);
    EXPECT_GE(chm_time_now(), t0 + 30 * kMs);
    t0 = chm_time_now();
    EXPECT_EQ(chm_msgq_receive_until(q, b, sizeof b, nullptr, t0 + 30 * kMs), -ETIMEDOUT);
    EXPECT_GE(chm_time_now(), t0 + 30 * kMs);
    ASSERT_EQ(chm_msgq_try_send(q, 1, 0, "m", 1), 0);
    t0 = chm_time_now();
    EXPECT_EQ(chm_msgq_send_until(q, 1, 0, "m", 1, t0 + 30 * kMs), -ETIMEDOUT);
    EXPECT_GE(chm_time_now(), t0 + 30 * kMs);
    EXPECT_EQ(chm_msgq_receive_until(q, b, sizeof b, nullptr, t0), 1) << "past, but there: taken";
    ASSERT_EQ(chm_rsem_v(s), 0);
    EXPECT_EQ(chm_rsem_p_until(s, t0), 0) << "past, but free: taken";
}

}  // namespace
}  // namespace chm::test
