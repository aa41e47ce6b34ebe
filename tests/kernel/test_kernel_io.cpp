// Blocking UNIX calls park only the calling task (chimera/io.h): sleeps,
// reads and writes on pipes and sockets, poll. A 2 ms "ticker" periodic
// task proves the RTPU kept running meanwhile: the longest gap between two
// of its cycles stays far below the wait (a blocked RTPU would show one gap
// as long as the wait, then a burst of late cycles). Every wait is bounded;
// nothing asserts speed.
#include <cerrno>
#include <chrono>
#include <cstring>
#include <ctime>
#include <poll.h>
#include <sys/socket.h>
#include <thread>
#include <unistd.h>
#include <vector>

#include "chimera/io.h"
#include "gap_ticker.hpp"
#include "kernel_fixture.hpp"
#include "port.hpp"

namespace chm::test {
namespace {

int g_fd[2];

struct Outcome {
    ssize_t r = -2;
    int err = 0;
    uint64_t waited = 0;
    int ticks_during = 0;
    uint64_t max_gap = 0;  // the ticker's longest gap during the call
    double cpu_s = 0;
    char buf[64] = {};
};
Outcome g_out;

double thread_cpu_s() {  // the kernel thread's CPU time, read from a task
    timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return double(ts.tv_sec) + double(ts.tv_nsec) * 1e-9;
}

// Runs `body` timed in a task, records the outcome, then stops the ticker.
template <class Body>
void measured(Body body) {
    const int t0 = GapTicker::cycles;
    GapTicker::max_gap = 0;
    const uint64_t a = chm_time_now();
    const double c0 = thread_cpu_s();
    errno = 0;
    g_out.r = body();
    g_out.err = errno;
    g_out.cpu_s = thread_cpu_s() - c0;
    g_out.waited = chm_time_now() - a;
    g_out.ticks_during = GapTicker::cycles - t0;
    g_out.max_gap = GapTicker::max_gap;
    GapTicker::stop = true;
}

// The ticker ran throughout the call: several cycles, and no gap as long
// as the call (a blocked RTPU shows one gap of the whole call; the 3/4
// bound leaves room for a loaded host descheduling the process a while).
void expect_rtpu_kept_running() {
    EXPECT_GT(g_out.ticks_during, 3);
    EXPECT_LT(g_out.max_gap * 4, g_out.waited * 3)
        << "the ticker stood still for " << g_out.max_gap << " ns of a " << g_out.waited
        << " ns call: the call blocked the RTPU";
}

class BlockingIo : public KernelTest {
protected:
    void SetUp() override {
        GapTicker::reset();
        g_out = Outcome{};
        ASSERT_EQ(pipe(g_fd), 0);
    }
    void TearDown() override {
        if (helper_.joinable()) helper_.join();
        close(g_fd[0]);
        close(g_fd[1]);
        KernelTest::TearDown();
    }
    void start_with_ticker() {
        start(CHM_SCHED_MUF, false);
        spawn(GapTicker::body, nullptr, "ticker", 5, 2 * kMs, 50 * kUs);
    }
    // A foreign thread writes `msg` into `fd` after `delay_ms`.
    void write_later(int fd, const char* msg, int delay_ms) {
        helper_ = std::thread([=] {
            std::this_thread::sleep_for(std::chrono::milliseconds(delay_ms));
            (void)::write(fd, msg, strlen(msg));
        });
    }
    std::thread helper_;
};

void sleeper(void*) {
    measured([] {
        usleep(60000);
        timespec ts{0, 40 * long(kMs)};
        return ssize_t(nanosleep(&ts, nullptr));
    });
}

TEST_F(BlockingIo, SleepParksOnlyTheCaller) {
    start_with_ticker();
    spawn(sleeper, nullptr, "sleeper", 1);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_out.r, 0);
    EXPECT_GE(g_out.waited, 100 * kMs);
    expect_rtpu_kept_running();
}

void reader(void*) {
    measured([] { return ::read(g_fd[0], g_out.buf, sizeof g_out.buf); });
}

TEST_F(BlockingIo, ReadOnAnEmptyPipeParksUntilDataArrives) {
    start_with_ticker();
    spawn(reader, nullptr, "reader", 1);
    write_later(g_fd[1], "hello", 100);
    ASSERT_EQ(chm_kernel_run(), 0);
    ASSERT_EQ(g_out.r, 5);
    EXPECT_STREQ(g_out.buf, "hello");
    EXPECT_GE(g_out.waited, 90 * kMs);
    expect_rtpu_kept_running();
}

TEST_F(BlockingIo, AnIdleRtpuWaitsOnTheDescriptorWithoutSpinning) {
    start(CHM_SCHED_MUF, false);
    spawn(reader, nullptr, "reader", 1);
    write_later(g_fd[1], "wake", 300);
    ASSERT_EQ(chm_kernel_run(), 0);
    ASSERT_EQ(g_out.r, 4);
    EXPECT_GE(g_out.waited, 290 * kMs);
    EXPECT_LT(g_out.cpu_s, 0.15) << "the kernel thread spun while waiting on the pipe";
}

// While a task is parked on a descriptor the RTPU sleeps in ppoll, and a
// tick wakes it there. That path forgot the repeating timer (armed_at = 0)
// and re-armed it after every tick: a timer_settime per cycle of a 1 kHz
// task (~1 arm per cycle here). The idle loop's own path keeps it armed
// (about one arm per 1,000 periods, docs/architecture.md, "Time").
TEST_F(BlockingIo, APeriodicTaskBesideAParkedReadDoesNotReArmTheTimerEveryCycle) {
    start(CHM_SCHED_MUF, false);
    spawn(GapTicker::body, nullptr, "ticker", 5, 1 * kMs, 0);
    spawn(reader, nullptr, "reader", 1);
    write_later(g_fd[1], "done", 300);
    const std::uint64_t arms0 = chm::port::timer_arm_count();
    ASSERT_EQ(chm_kernel_run(), 0);
    const std::uint64_t arms = chm::port::timer_arm_count() - arms0;
    ASSERT_EQ(g_out.r, 4);
    EXPECT_GT(GapTicker::cycles, 50);
    EXPECT_LT(arms * 4, std::uint64_t(GapTicker::cycles))
        << arms << " timer arms for " << GapTicker::cycles << " cycles";
}

constexpr size_t kBig = 256 * 1024;  // four times a pipe's capacity
void big_writer(void*) {
    static std::vector<unsigned char> data(kBig);
    for (size_t i = 0; i < kBig; ++i) data[i] = static_cast<unsigned char>(i * 131 + i / 251);
    measured([] { return ::write(g_fd[1], data.data(), kBig); });
}

TEST_F(BlockingIo, BigWriteToAFullPipeParksBetweenPieces) {
    start_with_ticker();
    spawn(big_writer, nullptr, "writer", 1);
    std::vector<unsigned char> got;
    helper_ = std::thread([&] {
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
        unsigned char b[4096];
        while (got.size() < kBig) {
            pollfd p{g_fd[0], POLLIN, 0};
            if (::poll(&p, 1, 10000) != 1) break;  // bounded: a lost write fails, never hangs
            const ssize_t n = ::read(g_fd[0], b, sizeof b);
            if (n <= 0) break;
            got.insert(got.end(), b, b + n);
            std::this_thread::sleep_for(std::chrono::microseconds(200));
        }
    });
    ASSERT_EQ(chm_kernel_run(), 0);
    helper_.join();
    EXPECT_EQ(g_out.r, ssize_t(kBig)) << "errno " << g_out.err;
    ASSERT_EQ(got.size(), kBig);
    for (size_t i = 0; i < kBig; ++i)
        ASSERT_EQ(got[i], static_cast<unsigned char>(i * 131 + i / 251)) << "byte " << i;
    expect_rtpu_kept_running();
}

void poller(void*) {
    measured([] {
        pollfd p{g_fd[0], POLLIN, 0};
        return ssize_t(::poll(&p, 1, 50));
    });
}

TEST_F(BlockingIo, PollTimesOutWhileOthersRun) {
    start_with_ticker();
    spawn(poller, nullptr, "poller", 1);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_out.r, 0);
    EXPECT_GE(g_out.waited, 50 * kMs);
    expect_rtpu_kept_running();
}

// chm_io_poll's timeout (chimera/kernel.h, "Timeouts"): CHM_NO_WAIT only
// looks; CHM_FOREVER and a -1 from a caller of the old int64_t signature
// (it converts to CHM_FOREVER) wait for the data however long it takes.
std::uint64_t g_poll_timeout = 0;
void io_poller(void*) {
    measured([] {
        pollfd p{g_fd[0], POLLIN, 0};
        const int looked = chm_io_poll(&p, 1, CHM_NO_WAIT);
        if (looked != 0) return ssize_t(100 + looked);  // nothing written yet
        const int r = chm_io_poll(&p, 1, g_poll_timeout);
        return r == 1 && (p.revents & POLLIN) ? ssize_t(::read(g_fd[0], g_out.buf, sizeof g_out.buf)) : ssize_t(r);
    });
}

TEST_F(BlockingIo, IoPollForeverWaitsForTheData) {
    const std::int64_t old_forever = -1;  // what callers passed before: still no limit
    for (const std::uint64_t t : {CHM_FOREVER, std::uint64_t(old_forever)}) {
        ASSERT_EQ(t, CHM_FOREVER);
        g_out = Outcome{};
        GapTicker::reset();
        g_poll_timeout = t;
        start_with_ticker();
        spawn(io_poller, nullptr, "poller", 1);
        write_later(g_fd[1], "late", 120);
        ASSERT_EQ(chm_kernel_run(), 0);
        helper_.join();
        chm_kernel_fini();
        started_ = false;
        EXPECT_EQ(g_out.r, 4) << "100+: CHM_NO_WAIT saw data that was not there";
        EXPECT_STREQ(g_out.buf, "late");
        EXPECT_GE(g_out.waited, 100 * kMs);
        expect_rtpu_kept_running();
    }
}

int g_sock[2];
void receiver(void*) {
    measured([] { return ::recv(g_sock[0], g_out.buf, sizeof g_out.buf, 0); });
}

TEST_F(BlockingIo, RecvOnASocketParksUntilDataArrives) {
    ASSERT_EQ(socketpair(AF_UNIX, SOCK_STREAM, 0, g_sock), 0);
    start_with_ticker();
    spawn(receiver, nullptr, "receiver", 1);
    write_later(g_sock[1], "datagram", 80);
    ASSERT_EQ(chm_kernel_run(), 0);
    helper_.join();
    close(g_sock[0]);
    close(g_sock[1]);
    ASSERT_EQ(g_out.r, 8);
    EXPECT_STREQ(g_out.buf, "datagram");
    expect_rtpu_kept_running();
}

volatile int g_handled = 0;
chm_tid_t g_reader_id;
void on_usig(int, void*) { g_handled = g_handled + 1; }
void interruptible_reader(void*) {
    (void)chm_usig_handle(3, on_usig, nullptr);
    measured([] { return ::read(g_fd[0], g_out.buf, sizeof g_out.buf); });
}
void signaller(void*) {
    usleep(20000);
    (void)chm_usig_send(g_reader_id, 3);
}

TEST_F(BlockingIo, AUserSignalInterruptsARead) {
    start(CHM_SCHED_MUF, false);
    g_handled = 0;
    g_reader_id = spawn(interruptible_reader, nullptr, "reader", 2);
    spawn(signaller, nullptr, "signaller", 1);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_out.r, -1);
    EXPECT_EQ(g_out.err, EINTR);
    EXPECT_EQ(g_handled, 1);
}

void parked_forever(void*) {
    char c;
    (void)::read(g_fd[0], &c, 1);
    ADD_FAILURE() << "the destroyed task ran on";
}
chm_tid_t g_victim;
void destroyer(void*) {
    usleep(20000);
    EXPECT_EQ(chm_task_destroy(g_victim), 0);
    GapTicker::stop = true;
}

TEST_F(BlockingIo, DestroyingAParkedTaskLeavesNothingBehind) {
    start_with_ticker();
    g_victim = spawn(parked_forever, nullptr, "victim", 1);
    spawn(destroyer, nullptr, "destroyer", 2);
    ASSERT_EQ(chm_kernel_run(), 0);
    // The pipe becoming readable later finds nobody waiting.
    ASSERT_EQ(::write(g_fd[1], "x", 1), 1);
    EXPECT_EQ(chm_task_count(), 0);
}

TEST_F(BlockingIo, OutsideATaskTheCallsAreLibcs) {
    ASSERT_EQ(::write(g_fd[1], "abc", 3), 3);
    char b[4] = {};
    EXPECT_EQ(::read(g_fd[0], b, 3), 3);
    EXPECT_STREQ(b, "abc");
    timespec ts{0, 1000000};
    EXPECT_EQ(nanosleep(&ts, nullptr), 0);
    pollfd p{g_fd[0], POLLIN, 0};
    EXPECT_EQ(::poll(&p, 1, 1), 0);
}

// On the virtual clock a sleep takes exactly its virtual time, at once.
void virtual_sleeper(void*) {
    measured([] { return ssize_t(sleep(5)); });
}

TEST_F(BlockingIo, SleepOnTheVirtualClockIsExact) {
    start(CHM_SCHED_MUF, true);
    spawn(virtual_sleeper, nullptr, "sleeper", 1);
    const auto t0 = std::chrono::steady_clock::now();
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_out.r, 0);
    EXPECT_EQ(g_out.waited, 5000 * kMs);
    EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(4));
}

}  // namespace
}  // namespace chm::test
