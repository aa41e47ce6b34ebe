// A task's spin before it parks (kernel/sync/remote_wait.cpp): on an RTPU
// that polls (idle_poll_ns) and has nothing else to run, a task whose
// remote wait must block first spins on its word in its own context, the
// word marked watched. With real RTPU processes: a grant then needs no
// ring and no switch; a task that cannot spin parks and the idle poll
// watches it; a task made ready ends the spin, a more urgent one preempts
// it, a user signal interrupts it, and its timeout holds. Each RTPU polls
// for tens of seconds, so only what the spin is checked for can end it;
// every wait is bounded, nothing asserts speed.
#include <cerrno>

#include "chimera/chimera.h"
#include "chimera/msgq.h"
#include "chimera/rsem.h"
#include "chimera/shm.h"
#include "chimera/usig.h"
#include "ipc_fixture.hpp"
#include "rsem_fixture.hpp"
#include "kernel/kernel.hpp"  // the kernel's switch count
#include "port.hpp"
#include "rtpu_child.hpp"

namespace chm::test {
namespace {

constexpr int64_t kWait = 30'000'000'000;  // 30 s: only a broken wake-up takes this long
constexpr uint64_t kMs = 1'000'000;
constexpr uint64_t kPollLong = 60'000'000'000;  // each RTPU polls 60 s before it sleeps

void pause_ms(uint64_t ms) { chm_task_pause_until(chm_time_now() + ms * kMs); }

// What the waiting task saw, reported through the child's exit code.
volatile int g_result = 1;            // its chm_rsem_p_timed result
volatile uint64_t g_switches = 0;     // the RTPU's switches during that call
volatile uint64_t g_parks = 0;        // its remote waits that parked the task
volatile uint64_t g_waited_ns = 0;    // how long the call took
volatile int g_handled = 0;           // user signals handled
chm_tid_t g_waiter = CHM_TID_NONE;

// Waits on "sem" (after a pause of `arg` ms, so tasks spawned with it can
// block first) with the timeout kWait.
void waiter(void* arg) {
    if (arg) pause_ms(reinterpret_cast<uintptr_t>(arg));
    chm_rsem_t* s = open_sem("sem");
    if (!s) return;
    const uint64_t sw = chm::kernel::g_k.switches;
    const uint64_t t0 = chm_time_now();
    g_result = chm_rsem_p_timed(s, kWait);
    g_waited_ns = chm_time_now() - t0;
    g_switches = chm::kernel::g_k.switches - sw;
}

class Spin : public RsemTest {
protected:
    void SetUp() override {
        IpcTest::SetUp();
        create();
        ASSERT_EQ(chm_bp_attach_host(path_.c_str(), "test", nullptr), 0) << chm_bp_last_error();
        sem_ = make("sem");
        flag_ = make("flag");
    }
    // RTPU 1 (FIXED policy, polling kPollLong) runs `tasks`; it exits with
    // check()'s verdict on what the waiter saw.
    template <class Tasks, class Check>
    pid_t rtpu(Tasks tasks, Check check) {
        const std::string path = path_;
        return spawn([=] {
            const int r = run_rtpu(path, 1, tasks, RtpuOptions{CHM_SCHED_FIXED, kPollLong});
            return r ? r : check();
        });
    }
    // The host's V of "sem", and the doorbell rings it made.
    int v_rings() {
        const std::uint32_t before = chm::port::doorbell_rings_sent();
        EXPECT_EQ(chm_rsem_v(sem_), 0);
        return int(chm::port::doorbell_rings_sent() - before);
    }
    chm_rsem_t* sem_ = nullptr;
    chm_rsem_t* flag_ = nullptr;
};

// The only task of a polling RTPU spins for its grant: the V finds the
// word watched and rings nothing, and the task never leaves the CPU.
TEST_F(Spin, AGrantToASpinningTaskNeedsNoRingAndNoSwitch) {
    const pid_t child = rtpu([] { return spawn_task(waiter, nullptr, "waiter", 5) != CHM_TID_NONE; },
                             [] { return g_result != 0 ? 60 : g_switches != 0 ? 61 : 0; });
    ASSERT_TRUE(until_waiting(sem_, 1));
    sleep_us(20000);
    EXPECT_EQ(v_rings(), 0);
    EXPECT_EQ(reap(child), 0) << "60: no grant; 61: the waiter parked";
}

// A task that finds another ready parks at once; once the RTPU is idle its
// poll watches the parked task's word: again no ring.
void busy_then_flag(void*) {
    const uint64_t end = chm_time_now() + 100 * kMs;
    while (chm_time_now() < end) {
    }
    if (chm_rsem_t* f = open_sem("flag")) (void)chm_rsem_v(f);
}

TEST_F(Spin, ATaskThatCannotSpinParksAndTheIdlePollWatchesIt) {
    const pid_t child = rtpu(
        [] {
            return spawn_task(waiter, nullptr, "waiter", 5) != CHM_TID_NONE &&
                   spawn_task(busy_then_flag, nullptr, "busy", 1) != CHM_TID_NONE;
        },
        [] { return g_result != 0 ? 60 : g_switches == 0 ? 61 : 0; });
    ASSERT_EQ(chm_rsem_p_timed(flag_, kWait), 0) << "the busy task never finished";
    sleep_us(20000);  // the RTPU is in its idle loop, polling
    EXPECT_EQ(v_rings(), 0);
    EXPECT_EQ(reap(child), 0) << "60: no grant; 61: the waiter never parked";
}

// A lower-priority task made ready (its pause ends) ends the spin: the
// waiter parks and the task runs, long before the 60 s poll would end.
void pause_then_flag(void*) {
    pause_ms(100);
    if (chm_rsem_t* f = open_sem("flag")) (void)chm_rsem_v(f);
}

TEST_F(Spin, ATaskMadeReadyEndsTheSpin) {
    const pid_t child = rtpu(
        [] {
            return spawn_task(waiter, reinterpret_cast<void*>(uintptr_t(5)), "waiter", 5) != CHM_TID_NONE &&
                   spawn_task(pause_then_flag, nullptr, "late", 1) != CHM_TID_NONE;
        },
        [] { return g_result != 0 ? 60 : 0; });
    ASSERT_TRUE(until_waiting(sem_, 1));
    EXPECT_EQ(chm_rsem_p_timed(flag_, kWait), 0) << "the spin kept the lower-priority task from running";
    EXPECT_EQ(chm_rsem_waiting(sem_), 1);  // still waiting, parked now
    (void)chm_rsem_v(sem_);
    EXPECT_EQ(reap(child), 0);
}

// A more urgent task whose pause ends preempts the spinning task; the
// spin goes on after it and still takes the grant without a ring.
TEST_F(Spin, AMoreUrgentTaskPreemptsTheSpin) {
    const pid_t child = rtpu(
        [] {
            return spawn_task(waiter, nullptr, "waiter", 5) != CHM_TID_NONE &&
                   spawn_task(pause_then_flag, nullptr, "urgent", 9) != CHM_TID_NONE;
        },
        [] { return g_result != 0 ? 60 : 0; });
    EXPECT_EQ(chm_rsem_p_timed(flag_, kWait), 0) << "the spin kept the more urgent task from running";
    ASSERT_TRUE(until_waiting(sem_, 1));
    sleep_us(20000);
    EXPECT_EQ(v_rings(), 0);  // watched: by the spin, or by the idle poll
    EXPECT_EQ(reap(child), 0);
}

// A user signal interrupts the spin as it would the parked wait: the
// handler runs and chm_rsem_p returns -EINTR, its record withdrawn.
void on_signal(int, void*) { g_handled = g_handled + 1; }

void signalled_waiter(void*) {
    (void)chm_usig_handle(1, on_signal, nullptr);
    waiter(nullptr);
}

// Signals the waiter once its record is written (its wait has begun).
void signaller(void*) {
    chm_rsem_t* s = open_sem("sem");
    for (int i = 0; s && i < 2000 && chm_rsem_waiting(s) != 1; ++i) pause_ms(5);
    pause_ms(20);
    (void)chm_usig_send(g_waiter, 1);
}

TEST_F(Spin, AUserSignalInterruptsTheSpin) {
    const pid_t child = rtpu(
        [] {
            g_waiter = spawn_task(signalled_waiter, nullptr, "waiter", 5);
            return g_waiter != CHM_TID_NONE && spawn_task(signaller, nullptr, "signaller", 9) != CHM_TID_NONE;
        },
        [] { return g_result != -EINTR ? 60 : g_handled != 1 ? 61 : 0; });
    EXPECT_EQ(reap(child), 0) << "60: the wait was not interrupted; 61: the handler did not run once";
    EXPECT_EQ(chm_rsem_waiting(sem_), 0);
    EXPECT_EQ(chm_rsem_value(sem_), 0);
}

// The spin counts against the wait's timeout: a 100 ms timeout ends the
// wait after about 100 ms, not after the 60 s poll.
void timed_waiter(void*) {
    chm_rsem_t* s = open_sem("sem");
    if (!s) return;
    const uint64_t t0 = chm_time_now();
    g_result = chm_rsem_p_timed(s, 100 * kMs);
    g_waited_ns = chm_time_now() - t0;
}

TEST_F(Spin, TheSpinKeepsToTheTimeout) {
    const pid_t child = rtpu([] { return spawn_task(timed_waiter, nullptr, "waiter", 5) != CHM_TID_NONE; },
                             [] {
                                 if (g_result != -ETIMEDOUT) return 60;
                                 return g_waited_ns < 100 * kMs ? 61 : g_waited_ns > 20000 * kMs ? 62 : 0;
                             });
    EXPECT_EQ(reap(child), 0) << "60: not -ETIMEDOUT; 61: early; 62: the spin outlasted the timeout";
    EXPECT_EQ(chm_rsem_waiting(sem_), 0);
}

// A message queue's receiver spins the same way: a send to it rings
// nothing, and the receiver never parks. (It may still leave the CPU
// after the grant: it takes the queue's lock to copy the message, which
// the sender holds as it grants, and a lock held past its 20 us spin
// gives the CPU away between tests; under qemu it sometimes is. Parks,
// not switches, are what a spin saves.)
void receiver(void*) {
    chm_msgq_t* q = nullptr;
    if (chm_msgq_open("q", &q) != 0) return;
    char buf[32];
    const uint64_t parks = chm::kernel::g_k.remote_parks;
    g_result = chm_msgq_receive_timed(q, buf, sizeof buf, nullptr, kWait);
    g_parks = chm::kernel::g_k.remote_parks - parks;
}

TEST_F(Spin, AMessageToASpinningReceiverNeedsNoRingAndNoSwitch) {
    chm_msgq_t* q = nullptr;
    ASSERT_EQ(chm_msgq_create("q", nullptr, CHM_MSGQ_COMMON, &q), 0) << chm_bp_last_error();
    const pid_t child = rtpu([] { return spawn_task(receiver, nullptr, "receiver", 5) != CHM_TID_NONE; },
                             [] { return g_result != 3 ? 60 : g_parks != 0 ? 61 : 0; });
    chm_msgq_info_t info{};
    const uint64_t end = now_ns() + 10000 * kMs;
    while (now_ns() < end && (chm_msgq_info(q, &info) != 0 || info.receivers_waiting != 1)) sleep_us(200);
    ASSERT_EQ(info.receivers_waiting, 1u);
    sleep_us(20000);
    const std::uint32_t before = chm::port::doorbell_rings_sent();
    ASSERT_EQ(chm_msgq_send(q, 1, 0, "abc", 3), 0);
    EXPECT_EQ(int(chm::port::doorbell_rings_sent() - before), 0);
    EXPECT_EQ(reap(child), 0) << "60: no message; 61: the receiver parked";
}

}  // namespace
}  // namespace chm::test
