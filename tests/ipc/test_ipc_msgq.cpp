// Message queues between real processes: receive orders, typed
// variable-length messages, capacity, non-blocking and timed calls, bad
// input, RTPU tasks that park alone while host processes sleep on the
// futex, the most urgent waiter first, message accounting under load.
// Death and repair: test_ipc_msgq_robust.cpp.
#include <set>

#include <sys/mman.h>

#include "chimera/chimera.h"
#include "chimera/msgq.h"
#include "ipc/msgq/msgq.hpp"
#include "ipc/wake/wake.hpp"
#include "msgq_fixture.hpp"

namespace chm::test {
namespace {

using IpcMsgq = MsgqTest;

TEST_F(IpcMsgq, FifoLifoAndPriorityOrder) {
    create();
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0);
    const chm_msgq_order orders[] = {CHM_MSGQ_FIFO, CHM_MSGQ_LIFO, CHM_MSGQ_PRIORITY};
    const std::uint32_t prios[] = {3, 7, 3, 0, 31, 7, 3};  // sent in this order, payload = index
    for (chm_msgq_order order : orders) {
        SCOPED_TRACE(order);
        chm_msgq_t* q = make_queue("ord", order, 32, 16);
        ASSERT_NE(q, nullptr);
        for (std::uint32_t i = 0; i < 7; ++i) ASSERT_EQ(chm_msgq_try_send(q, 100 + i, prios[i], &i, sizeof i), 0);
        std::vector<std::uint32_t> got;
        for (;;) {
            std::uint32_t v = 0;
            chm_msgq_msg_info_t info{};
            const int n = chm_msgq_try_receive(q, &v, sizeof v, &info);
            if (n == -EAGAIN) break;
            ASSERT_EQ(n, int(sizeof v));
            EXPECT_EQ(info.type, 100 + v);  // the type travels with its message
            EXPECT_EQ(info.prio, prios[v]);
            EXPECT_EQ(info.sender, chm_bp_self());
            got.push_back(v);
        }
        const std::vector<std::uint32_t> want =
            order == CHM_MSGQ_FIFO ? std::vector<std::uint32_t>{0, 1, 2, 3, 4, 5, 6}
            : order == CHM_MSGQ_LIFO ? std::vector<std::uint32_t>{6, 5, 4, 3, 2, 1, 0}
                                     : std::vector<std::uint32_t>{4, 1, 5, 0, 2, 6, 3};  // FIFO among equals
        EXPECT_EQ(got, want);
        EXPECT_EQ(check(q), "");
        ASSERT_EQ(chm_msgq_close(q), 0);
        ASSERT_EQ(chm_msgq_destroy("ord"), 0);
    }
}

TEST_F(IpcMsgq, TypedVariableLengthMessagesRoundTripAcrossProcesses) {
    create();
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0);
    chm_msgq_t* q = make_queue("var", CHM_MSGQ_FIFO, 1000, 8, 2);  // in RTPU 2's window
    ASSERT_NE(q, nullptr);
    constexpr int kMsgs = 300;
    const pid_t c = spawn([&] {
        if (chm_bp_join(path_.c_str(), 1, nullptr)) return 1;
        chm_msgq_t* h = nullptr;
        if (chm_msgq_open("var", &h)) return 2;
        unsigned char buf[1000];
        for (int i = 0; i < kMsgs; ++i) {
            const std::size_t len = std::size_t(i * 37) % 1001;  // 0..1000, the edges included
            for (std::size_t k = 0; k < len; ++k) buf[k] = static_cast<unsigned char>(i + k);
            if (chm_msgq_send(h, 0xABC00000u + std::uint32_t(i), 0, buf, len)) return 3;
        }
        return chm_msgq_close(h) == 0 ? 0 : 4;
    });
    unsigned char buf[1000];
    for (int i = 0; i < kMsgs; ++i) {
        chm_msgq_msg_info_t info{};
        const int n = chm_msgq_receive_timed(q, buf, sizeof buf, &info, 10'000'000'000);
        const std::size_t len = std::size_t(i * 37) % 1001;
        ASSERT_EQ(n, int(len)) << i;
        EXPECT_EQ(info.type, 0xABC00000u + std::uint32_t(i));
        EXPECT_EQ(info.len, len);
        EXPECT_EQ(info.sender, 1);
        for (std::size_t k = 0; k < len; ++k) ASSERT_EQ(buf[k], static_cast<unsigned char>(i + k)) << i << " " << k;
    }
    EXPECT_EQ(reap(c), 0);
    EXPECT_EQ(check(q), "");
}

TEST_F(IpcMsgq, CapacityNonBlockingAndTimeouts) {
    create();
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0);
    chm_msgq_attr_t attr;
    chm_msgq_attr_init(&attr);
    attr.max_msg = 64;
    attr.max_count = 4;
    attr.max_bytes = 100;  // bytes run out before slots do for big messages
    chm_msgq_t* q = nullptr;
    ASSERT_EQ(chm_msgq_create("cap", &attr, CHM_MSGQ_COMMON, &q), 0) << chm_bp_last_error();
    char buf[64] = {};
    ASSERT_EQ(chm_msgq_try_send(q, 1, 0, buf, 60), 0);
    EXPECT_EQ(chm_msgq_try_send(q, 1, 0, buf, 60), -EAGAIN);  // 120 > 100 bytes
    ASSERT_EQ(chm_msgq_try_send(q, 2, 0, buf, 40), 0);        // exactly 100
    EXPECT_EQ(chm_msgq_try_send(q, 3, 0, buf, 1), -EAGAIN);
    ASSERT_EQ(chm_msgq_try_send(q, 3, 0, buf, 0), 0);         // empty messages take only a slot
    ASSERT_EQ(chm_msgq_try_send(q, 4, 0, nullptr, 0), 0);
    EXPECT_EQ(chm_msgq_try_send(q, 5, 0, nullptr, 0), -EAGAIN);  // 4 slots
    EXPECT_EQ(chm_msgq_send_timed(q, 5, 0, nullptr, 0, 0), -EAGAIN);
    std::uint64_t t0 = now_ns();
    EXPECT_EQ(chm_msgq_send_timed(q, 5, 0, nullptr, 0, 30'000'000), -ETIMEDOUT);
    std::uint64_t waited = now_ns() - t0;
    EXPECT_GE(waited, 30'000'000u);
    EXPECT_LT(waited, 5'000'000'000u);
    chm_msgq_info_t st;
    ASSERT_EQ(chm_msgq_info(q, &st), 0);
    EXPECT_EQ(st.count, 4u);
    EXPECT_EQ(st.bytes, 100u);
    EXPECT_EQ(st.senders_waiting, 0u);  // the timed-out sender took its record away

    // A receive buffer too small: refused, the message stays first.
    chm_msgq_msg_info_t info{};
    EXPECT_EQ(chm_msgq_try_receive(q, buf, 10, &info), -EMSGSIZE);
    EXPECT_EQ(info.len, 60u);
    ASSERT_EQ(chm_msgq_try_receive(q, buf, sizeof buf, &info), 60);
    EXPECT_EQ(info.type, 1u);
    for (std::uint32_t type = 2; type <= 4; ++type) {
        ASSERT_GE(chm_msgq_try_receive(q, buf, sizeof buf, &info), 0);
        EXPECT_EQ(info.type, type);
    }
    EXPECT_EQ(chm_msgq_try_receive(q, buf, sizeof buf, &info), -EAGAIN);
    EXPECT_EQ(chm_msgq_receive_timed(q, buf, sizeof buf, &info, 0), -EAGAIN);
    t0 = now_ns();
    EXPECT_EQ(chm_msgq_receive_timed(q, buf, sizeof buf, &info, 30'000'000), -ETIMEDOUT);
    waited = now_ns() - t0;
    EXPECT_GE(waited, 30'000'000u);
    EXPECT_LT(waited, 5'000'000'000u);
    std::printf("timed send/receive of 30 ms returned after %.2f ms\n", waited / 1e6);
    EXPECT_EQ(check(q), "");
}

TEST_F(IpcMsgq, BadInputIsRefusedAndChangesNothing) {
    create();
    chm_msgq_t* q = nullptr;
    EXPECT_EQ(chm_msgq_create("q", nullptr, CHM_MSGQ_COMMON, &q), -ENOTCONN);
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0);
    ASSERT_NE(q = make_queue("q", CHM_MSGQ_PRIORITY, 24, 4), nullptr);
    char buf[32] = {};
    ASSERT_EQ(chm_msgq_try_send(q, 9, 1, buf, 24), 0);
    chm_bp_status_t st0, st1;
    ASSERT_EQ(chm_bp_status(&st0), 0);
    chm_msgq_attr_t a;
    chm_msgq_t* x = nullptr;
    chm_msgq_attr_init(&a);
    a.order = chm_msgq_order(3);
    EXPECT_EQ(chm_msgq_create("x", &a, CHM_MSGQ_COMMON, &x), -EINVAL);
    EXPECT_NE(std::strstr(chm_bp_last_error(), "order"), nullptr) << chm_bp_last_error();
    chm_msgq_attr_init(&a);
    a.max_count = 0;
    EXPECT_EQ(chm_msgq_create("x", &a, CHM_MSGQ_COMMON, &x), -EINVAL);
    chm_msgq_attr_init(&a);
    a.max_msg = 0;
    EXPECT_EQ(chm_msgq_create("x", &a, CHM_MSGQ_COMMON, &x), -EINVAL);
    chm_msgq_attr_init(&a);
    a.max_bytes = 10;  // below max_msg
    EXPECT_EQ(chm_msgq_create("x", &a, CHM_MSGQ_COMMON, &x), -EINVAL);
    chm_msgq_attr_init(&a);
    a.max_waiters = CHM_MSGQ_WAITERS_MAX + 1;
    EXPECT_EQ(chm_msgq_create("x", &a, CHM_MSGQ_COMMON, &x), -EINVAL);
    chm_msgq_attr_init(&a);
    a.max_count = 100000;  // 100000 x 256 B: far beyond 256 KiB of common memory
    EXPECT_EQ(chm_msgq_create("x", &a, CHM_MSGQ_COMMON, &x), -ENOMEM);
    EXPECT_EQ(chm_msgq_create("x", nullptr, 8, &x), -ECHRNG);
    EXPECT_EQ(chm_msgq_create("", nullptr, CHM_MSGQ_COMMON, &x), -EINVAL);
    EXPECT_EQ(chm_msgq_create("a-name-that-is-much-longer-than-31", nullptr, CHM_MSGQ_COMMON, &x), -ENAMETOOLONG);
    EXPECT_EQ(chm_msgq_create("q", nullptr, CHM_MSGQ_COMMON, &x), -EEXIST);
    EXPECT_EQ(chm_msgq_create(nullptr, nullptr, CHM_MSGQ_COMMON, &x), -EINVAL);
    EXPECT_EQ(chm_msgq_open("nope", &x), -ENOENT);
    EXPECT_NE(std::strstr(chm_bp_last_error(), "nope"), nullptr) << chm_bp_last_error();
    EXPECT_EQ(chm_msgq_destroy("nope"), -ENOENT);
    EXPECT_EQ(x, nullptr);
    EXPECT_EQ(chm_msgq_try_send(q, 1, 0, buf, 25), -EMSGSIZE);  // max_msg 24
    EXPECT_EQ(chm_msgq_try_send(q, 1, CHM_MSGQ_PRIO_MAX + 1, buf, 1), -EINVAL);
    EXPECT_EQ(chm_msgq_try_send(q, 1, 0, nullptr, 1), -EINVAL);
    EXPECT_EQ(chm_msgq_try_receive(q, nullptr, 8, nullptr), -EINVAL);
    int local = 0;
    auto* fake = reinterpret_cast<chm_msgq_t*>(&local);
    EXPECT_EQ(chm_msgq_try_send(fake, 1, 0, buf, 1), -EINVAL);
    EXPECT_EQ(chm_msgq_try_receive(fake, buf, 8, nullptr), -EINVAL);
    EXPECT_EQ(chm_msgq_close(fake), -EINVAL);
    EXPECT_EQ(chm_msgq_try_send(nullptr, 1, 0, buf, 1), -EINVAL);
    // Nothing changed: same objects, same free memory, the one message.
    ASSERT_EQ(chm_bp_status(&st1), 0);
    EXPECT_EQ(st1.objects, st0.objects);
    EXPECT_EQ(st1.common_free, st0.common_free);
    chm_msgq_info_t info;
    ASSERT_EQ(chm_msgq_info(q, &info), 0);
    EXPECT_EQ(info.count, 1u);
    EXPECT_EQ(info.sent, 1u);
    EXPECT_EQ(check(q), "");
    // Close and destroy give the memory back.
    ASSERT_EQ(chm_msgq_destroy("q"), 0);
    EXPECT_EQ(chm_msgq_open("q", &x), -ENOENT);
    EXPECT_EQ(chm_msgq_try_send(q, 1, 0, buf, 1), -EIDRM);  // still open here
    ASSERT_EQ(chm_msgq_close(q), 0);
    ASSERT_EQ(chm_bp_status(&st1), 0);
    EXPECT_EQ(st1.objects, st0.objects - 1);
}

// --- an RTPU process with kernel tasks -----------------------------------

// Shared with the parent (MAP_SHARED before the fork).
struct Board {
    std::atomic<std::uint32_t> ticks;       // cycles of the periodic task
    std::atomic<std::uint32_t> blocked_at;  // ticks when the receiver blocked
    std::atomic<std::uint32_t> woken_at;    // ticks when it got its message
    std::atomic<std::uint32_t> order[8];    // receivers' priorities in the order served
    std::atomic<std::uint32_t> served;
};

Board* g_board;
chm_msgq_t* g_down;
chm_msgq_t* g_up;

void ticker(void*) {
    for (;;) {
        g_board->ticks.fetch_add(1);
        chm_task_wait_period();
    }
}

// Blocks in receive (parks), then answers on `up` once the host waits there.
void receiver(void*) {
    char buf[24];
    chm_msgq_msg_info_t info{};
    g_board->blocked_at = g_board->ticks.load();
    const int n = chm_msgq_receive_timed(g_down, buf, sizeof buf, &info, 20'000'000'000);
    g_board->woken_at = g_board->ticks.load();
    if (n != 14 || std::strcmp(buf, "wake up, task") != 0 || info.type != 77) chm_kernel_stop(10);
    chm_msgq_info_t st{};
    for (int i = 0; i < 20000 && ((void)chm_msgq_info(g_up, &st), st.receivers_waiting == 0); ++i)
        chm_task_pause_until(chm_time_now() + 1'000'000);
    if (st.receivers_waiting != 1) chm_kernel_stop(11);
    if (chm_msgq_send(g_up, 78, 0, "and you, host", 14)) chm_kernel_stop(12);
    chm_kernel_stop(0);
}

TEST_F(IpcMsgq, TaskParksAloneAndHostSleepsOnTheFutex) {
    create();
    auto* board = static_cast<Board*>(mmap(nullptr, sizeof(Board), PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS, -1, 0));
    ASSERT_NE(board, MAP_FAILED);
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0);
    chm_msgq_t* down = make_queue("down", CHM_MSGQ_FIFO, 24, 4);
    chm_msgq_t* up = make_queue("up", CHM_MSGQ_FIFO, 24, 4);
    ASSERT_TRUE(down && up);
    const pid_t c = spawn([&] {
        return run_rtpu(path_, 1, [&] {
            g_board = board;
            if (chm_msgq_open("down", &g_down) || chm_msgq_open("up", &g_up)) chm_kernel_stop(20);
            spawn_task(ticker, nullptr, "ticker", 1, 1'000'000);
            spawn_task(receiver, nullptr, "receiver", 5, 0);
        });
    });
    // The receiver is parked; its RTPU keeps running the periodic task.
    ASSERT_TRUE(wait_for([&] { return info(down).receivers_waiting == 1; }));
    const std::uint32_t t0 = board->ticks.load();
    ASSERT_TRUE(wait_for([&] { return board->ticks.load() >= t0 + 20; }));
    EXPECT_EQ(board->woken_at.load(), 0u);
    ASSERT_EQ(chm_msgq_send(down, 77, 0, "wake up, task", 14), 0);
    // The task answers once we sleep on the futex here.
    char buf[24];
    chm_msgq_msg_info_t in{};
    ASSERT_EQ(chm_msgq_receive_timed(up, buf, sizeof buf, &in, 20'000'000'000), 14)
        << chm_bp_last_error() << "; RTPU exit " << reap(c, 100);
    EXPECT_STREQ(buf, "and you, host");
    EXPECT_EQ(in.sender, 1);
    EXPECT_EQ(reap(c), 0);
    EXPECT_GE(board->woken_at.load() - board->blocked_at.load(), 20u);  // cycles while it was parked
    std::printf("periodic task ran %u cycles while its RTPU's receiver was parked\n",
                board->woken_at.load() - board->blocked_at.load());
    EXPECT_EQ(check(down), "");
    munmap(board, sizeof(Board));
}

// Priority 2 blocks first, then 5, then 9: first come would serve 2 first.
void ranked_receiver(void* arg) {
    const auto prio = std::uint32_t(reinterpret_cast<std::uintptr_t>(arg));
    const std::uint32_t before = prio == 2 ? 0 : prio == 5 ? 1 : 2;
    chm_msgq_info_t st{};
    while (chm_msgq_info(g_down, &st) == 0 && st.receivers_waiting < before)
        chm_task_pause_until(chm_time_now() + 1'000'000);
    char buf[24];
    if (chm_msgq_receive_timed(g_down, buf, sizeof buf, nullptr, 20'000'000'000) < 0) chm_kernel_stop(30);
    g_board->order[g_board->served.fetch_add(1)] = prio;
    if (g_board->served.load() == 3) chm_kernel_stop(0);
}

TEST_F(IpcMsgq, TheMostUrgentWaitingTaskIsServedFirst) {
    create();
    auto* board = static_cast<Board*>(mmap(nullptr, sizeof(Board), PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS, -1, 0));
    ASSERT_NE(board, MAP_FAILED);
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0);
    chm_msgq_t* down = make_queue("down", CHM_MSGQ_FIFO, 24, 4);
    ASSERT_NE(down, nullptr);
    const pid_t c = spawn([&] {
        return run_rtpu(path_, 2, [&] {
            g_board = board;
            if (chm_msgq_open("down", &g_down)) chm_kernel_stop(20);
            for (std::uintptr_t prio : {2, 9, 5}) spawn_task(ranked_receiver, reinterpret_cast<void*>(prio), "rx", int(prio), 0);
        });
    });
    ASSERT_TRUE(wait_for([&] { return info(down).receivers_waiting == 3; }));
    for (std::uint32_t k = 1; k <= 3; ++k) {
        ASSERT_EQ(chm_msgq_send(down, k, 0, "m", 2), 0);
        ASSERT_TRUE(wait_for([&] { return board->served.load() == k; })) << k;
    }
    EXPECT_EQ(reap(c), 0);
    EXPECT_EQ(board->order[0].load(), 9u);
    EXPECT_EQ(board->order[1].load(), 5u);
    EXPECT_EQ(board->order[2].load(), 2u);
    munmap(board, sizeof(Board));
}

TEST_F(IpcMsgq, EveryMessageArrivesOnceInOrderPerSenderAndPriority) {
    // Two sender processes into a small priority queue (so they block on a
    // full queue and are woken by the receiver), one receiving host.
    constexpr std::uint32_t kPerSender = 3000;
    create();
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0);
    chm_msgq_t* q = make_queue("acct", CHM_MSGQ_PRIORITY, 16, 8);
    ASSERT_NE(q, nullptr);
    struct Msg {
        std::uint32_t sender, seq, prio, check;
    };
    std::vector<pid_t> kids;
    for (int s = 1; s <= 2; ++s)
        kids.push_back(spawn([&, s] {
            if (chm_bp_join(path_.c_str(), s, nullptr)) return 1;
            chm_msgq_t* h = nullptr;
            if (chm_msgq_open("acct", &h)) return 2;
            unsigned seed = 77u * unsigned(s);
            for (std::uint32_t i = 0; i < kPerSender; ++i) {
                seed = seed * 1103515245u + 12345u;
                const Msg m{std::uint32_t(s), i, (seed >> 16) % 4, std::uint32_t(s) * 1000003u ^ i};
                if (chm_msgq_send_timed(h, 5, m.prio, &m, sizeof m, 20'000'000'000)) return 3;
            }
            return 0;
        }));
    std::set<std::pair<std::uint32_t, std::uint32_t>> seen;
    std::uint32_t last[3][4];  // per sender and priority: the last sequence number + 1
    std::memset(last, 0, sizeof last);
    for (std::uint32_t k = 0; k < 2 * kPerSender; ++k) {
        Msg m{};
        chm_msgq_msg_info_t in{};
        ASSERT_EQ(chm_msgq_receive_timed(q, &m, sizeof m, &in, 20'000'000'000), int(sizeof m)) << k;
        ASSERT_TRUE(m.sender == 1 || m.sender == 2);
        ASSERT_EQ(m.check, m.sender * 1000003u ^ m.seq);
        ASSERT_EQ(in.prio, m.prio);
        ASSERT_EQ(in.sender, std::int32_t(m.sender));
        ASSERT_TRUE(seen.insert({m.sender, m.seq}).second) << "twice: " << m.sender << "/" << m.seq;
        ASSERT_GE(m.seq, last[m.sender][m.prio]) << "out of order within a priority";
        last[m.sender][m.prio] = m.seq + 1;
    }
    for (pid_t k : kids) EXPECT_EQ(reap(k, 60000), 0);
    EXPECT_EQ(seen.size(), 2 * kPerSender);
    chm_msgq_info_t st = info(q);
    EXPECT_EQ(st.count, 0u);
    EXPECT_EQ(st.senders_waiting, 0u);
    EXPECT_EQ(check(q), "");
}

TEST_F(IpcMsgq, DestroyWakesABlockedReceiver) {
    create();
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0);
    chm_msgq_t* q = make_queue("gone", CHM_MSGQ_FIFO, 8, 2);
    ASSERT_NE(q, nullptr);
    Pipe ready;
    const pid_t c = spawn([&] {
        if (chm_bp_join(path_.c_str(), 3, nullptr)) return 1;
        chm_msgq_t* h = nullptr;
        if (chm_msgq_open("gone", &h)) return 2;
        ready.put('r');
        char buf[8];
        return chm_msgq_receive_timed(h, buf, sizeof buf, nullptr, 20'000'000'000) == -EIDRM ? 0 : 3;
    });
    ASSERT_EQ(ready.get(), 'r');
    ASSERT_TRUE(wait_for([&] { return info(q).receivers_waiting == 1; }));
    ASSERT_EQ(chm_msgq_destroy("gone"), 0);
    EXPECT_EQ(reap(c), 0);
    ASSERT_EQ(chm_msgq_close(q), 0);
}

}  // namespace
}  // namespace chm::test
