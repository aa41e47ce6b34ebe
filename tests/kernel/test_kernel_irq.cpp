// Interrupts (chimera/irq.h): mailbox vectors raised by foreign threads,
// lines bound to descriptors, enable/disable, interrupt-context rules.
// Every wait is bounded; nothing asserts speed.
#include <cerrno>
#include <chrono>
#include <functional>
#include <poll.h>
#include <thread>
#include <unistd.h>

#include "chimera/irq.h"
#include "chimera/sem.h"
#include "kernel_fixture.hpp"
#include "port.hpp"

namespace chm::test {
namespace {

class Irq : public KernelTest {
protected:
    void SetUp() override {
        ASSERT_EQ(chm_sem_init(&sem_, CHM_SEM_COUNTING, 0, 0), 0);
        g_sem = &sem_;
        g_woke = 0;
        g_stop = false;
        g_handler_p = 1;
    }
    void TearDown() override {
        if (helper_.joinable()) helper_.join();
        KernelTest::TearDown();
    }
    void later(int ms, std::function<void()> fn) {
        helper_ = std::thread([=] {
            std::this_thread::sleep_for(std::chrono::milliseconds(ms));
            fn();
        });
    }
    chm_sem_t sem_;
    std::thread helper_;

public:
    static inline chm_sem_t* g_sem;
    static inline volatile int g_woke;
    static inline volatile bool g_stop;
    static inline volatile int g_handler_p;
};

void v_handler(int, void*) { (void)chm_sem_v(Irq::g_sem); }

// Waits for the semaphore a handler Vs, `n` times, then stops everything.
void waiter(void* arg) {
    const int n = int(reinterpret_cast<intptr_t>(arg));
    for (int i = 0; i < n; ++i) {
        ASSERT_EQ(chm_sem_p_timed(Irq::g_sem, 5000 * kMs), 0) << "no interrupt came";
        Irq::g_woke = Irq::g_woke + 1;
    }
    Irq::g_stop = true;
}

void spinner(void*) {
    while (!Irq::g_stop) {
    }
}

TEST_F(Irq, AMailboxVectorRaisedByAForeignThreadWakesAnIdleRtpu) {
    start(CHM_SCHED_MUF, false);
    ASSERT_EQ(chm_irq_install(3, v_handler, nullptr), 0);
    spawn(waiter, reinterpret_cast<void*>(1), "waiter", 5);
    later(50, [] { (void)chm_irq_raise(3); });
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_woke, 1);
    EXPECT_EQ(chm_irq_count(3), 1u);
}

TEST_F(Irq, AnInterruptPreemptsABusyTaskForTheTaskItWakes) {
    start(CHM_SCHED_MUF, false);
    ASSERT_EQ(chm_irq_install(40, v_handler, nullptr), 0);
    spawn(waiter, reinterpret_cast<void*>(3), "waiter", 5);
    spawn(spinner, nullptr, "spinner", 1);  // only the waiter's end stops it
    later(30, [] {
        for (int i = 0; i < 3; ++i) {
            (void)chm_irq_raise(40);
            std::this_thread::sleep_for(std::chrono::milliseconds(20));
        }
    });
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_woke, 3);
}

TEST_F(Irq, ARaiseWhileDisabledIsHeldUntilEnabled) {
    start(CHM_SCHED_MUF, false);
    ASSERT_EQ(chm_irq_install(7, v_handler, nullptr), 0);
    ASSERT_EQ(chm_irq_disable(7), 0);
    ASSERT_EQ(chm_irq_raise(7), 0);
    ASSERT_EQ(chm_irq_raise(7), 0);  // one pending raise per vector, as on a line
    EXPECT_EQ(chm_irq_count(7), 0u);
    EXPECT_EQ(chm_sem_value(&sem_), 0);
    ASSERT_EQ(chm_irq_enable(7), 0);
    EXPECT_EQ(chm_irq_count(7), 1u);
    EXPECT_EQ(chm_sem_value(&sem_), 1);
}

// A driver's section shared with its handler: raised inside, delivered at
// the outermost unlock, not before.
void locked_section(void*) {
    chm_irq_lock();
    EXPECT_EQ(chm_irq_raise(5), 0);
    chm_irq_lock();  // nests
    const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(20);
    while (std::chrono::steady_clock::now() < until) {  // time for the doorbell's signal to land
    }
    chm_irq_unlock();
    EXPECT_EQ(chm_irq_count(5), 0u) << "delivered inside the section";
    chm_irq_unlock();
    EXPECT_EQ(chm_irq_count(5), 1u) << "not delivered at the outermost unlock";
    Irq::g_woke = 1;
}

TEST_F(Irq, ARaiseInsideALockedSectionIsDeliveredAtItsOutermostUnlock) {
    start(CHM_SCHED_MUF, false);
    ASSERT_EQ(chm_irq_install(5, v_handler, nullptr), 0);
    spawn(locked_section, nullptr, "driver", 5);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_woke, 1);
    EXPECT_EQ(chm_sem_value(&sem_), 1);
    // Off the kernel thread both calls do nothing (and nothing is left masked).
    std::thread([] {
        chm_irq_lock();
        chm_irq_unlock();
    }).join();
}

TEST_F(Irq, ARaiseBeforeAHandlerIsDeliveredOnInstall) {
    start(CHM_SCHED_MUF, false);
    ASSERT_EQ(chm_irq_raise(9), 0);
    ASSERT_EQ(chm_irq_install(9, v_handler, nullptr), 0);
    EXPECT_EQ(chm_irq_count(9), 1u);
}

int g_pipe[2];
void read_and_v(int, void*) {
    char c;
    if (::read(g_pipe[0], &c, 1) == 1) (void)chm_sem_v(Irq::g_sem);
}

TEST_F(Irq, ALineBoundToADescriptorFiresWhenItIsReadableIdleOrBusy) {
    ASSERT_EQ(pipe(g_pipe), 0);
    start(CHM_SCHED_MUF, false);
    ASSERT_EQ(chm_irq_install(33, read_and_v, nullptr), 0);
    ASSERT_EQ(chm_irq_attach_fd(33, g_pipe[0], POLLIN), 0);
    spawn(waiter, reinterpret_cast<void*>(2), "waiter", 5);
    // First byte while the RTPU idles (ppoll), second while a task spins
    // (the IoPoll tick).
    later(40, [] {
        (void)::write(g_pipe[1], "a", 1);
        std::this_thread::sleep_for(std::chrono::milliseconds(40));
        (void)::write(g_pipe[1], "b", 1);
    });
    spawn(spinner, nullptr, "spinner", 1);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_woke, 2);
    EXPECT_EQ(chm_irq_count(33), 2u);
    EXPECT_EQ(chm_irq_detach_fd(33), 0);
    close(g_pipe[0]);
    close(g_pipe[1]);
}

void p_in_handler(int, void*) { Irq::g_handler_p = chm_sem_p(Irq::g_sem); }

void raise_then_stop(void*) { (void)chm_irq_raise(12); }

TEST_F(Irq, AHandlerThatWouldWaitIsRefused) {
    start(CHM_SCHED_MUF, false);
    ASSERT_EQ(chm_irq_install(12, p_in_handler, nullptr), 0);
    spawn(raise_then_stop, nullptr, "raiser", 1);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_handler_p, -EPERM);
}

TEST_F(Irq, BadArgumentsAreNamed) {
    EXPECT_EQ(chm_irq_install(1, v_handler, nullptr), -EPERM) << "no kernel yet";
    start(CHM_SCHED_MUF, false);
    EXPECT_EQ(chm_irq_install(-1, v_handler, nullptr), -EINVAL);
    EXPECT_EQ(chm_irq_install(64, v_handler, nullptr), -EINVAL);
    EXPECT_EQ(chm_irq_install(1, nullptr, nullptr), -EINVAL);
    ASSERT_EQ(chm_irq_install(1, v_handler, nullptr), 0);
    EXPECT_EQ(chm_irq_install(1, v_handler, nullptr), -EBUSY);
    EXPECT_EQ(chm_irq_remove(2), -ENOENT);
    EXPECT_EQ(chm_irq_attach_fd(1, 0, POLLIN), -EINVAL) << "mailbox vectors take no descriptor";
    EXPECT_EQ(chm_irq_attach_fd(40, -1, POLLIN), -EINVAL);
    EXPECT_EQ(chm_irq_attach_fd(40, 0, 0), -EINVAL);
    EXPECT_EQ(chm_irq_detach_fd(40), -ENOENT);
    EXPECT_EQ(chm_irq_raise(99), -EINVAL);
    EXPECT_EQ(chm_irq_remove(1), 0);
}

}  // namespace
}  // namespace chm::test

namespace chm::test {
namespace {

// With idle_poll_ns the idle RTPU spins on its doorbell before sleeping; a
// ring then is just the bit: no futex wake, no signal. The raiser sees the
// polling state and the waiting task still wakes.
class IrqPoll : public Irq {};

TEST_F(IrqPoll, ARingWhileTheRtpuPollsItsDoorbellWakesTheTask) {
    chm_kernel_config_t cfg;
    chm_kernel_config_init(&cfg);
    cfg.idle_poll_ns = 2000 * kMs;  // longer than the test: it never sleeps
    ASSERT_EQ(chm_kernel_init(&cfg), 0);
    started_ = true;
    ASSERT_EQ(chm_irq_install(4, v_handler, nullptr), 0);
    spawn(waiter, reinterpret_cast<void*>(1), "waiter", 5);
    static volatile uint32_t seen_state = 99;
    later(30, [] {
        seen_state = __atomic_load_n(chm::port::doorbell().state, __ATOMIC_SEQ_CST);
        (void)chm_irq_raise(4);
    });
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_woke, 1);
    EXPECT_EQ(seen_state, uint32_t(chm::port::kDbPolling)) << "the idle RTPU was not polling";
}

}  // namespace
}  // namespace chm::test
