// Bounded waits (issue 15, item 7): a live process stalled inside a
// backplane call (held at a named stop point, SIGSTOP) holds an internal
// lock; try calls return at once, a V within its bound, and chm_bp_leave,
// exit and fork return while this process's monitor thread is recovering
// a dead peer behind that lock. The bounds are docs/backplane.md's ("Every
// wait and its bound"); the assertions allow far more than each bound, and
// far less than the 5 s (or the hang) each wait took before. Every child
// is bounded, and killed and reaped by the fixture even when a test fails.
#include <cstdlib>
#include <set>
#include <string>

#include <dirent.h>
#include <pthread.h>

#include "chimera/irq.h"
#include "chimera/msgq.h"
#include "chimera/rsem.h"
#include "ipc_fixture.hpp"
#include "rsem_fixture.hpp"
#include "rtpu_child.hpp"

namespace chm::test {
namespace {

enum class Ending { kLeave, kExit, kFork };

class IpcBounds : public RsemTest {
protected:
    void ends_while_the_monitor_waits(Ending how);
    // A child that attaches, opens semaphore `name` and stops inside
    // chm_rsem_v holding its lock ("rsem.v.locked"); let go (SIGCONT), its
    // V lands and it leaves: exit status 0.
    pid_t stall_in_v(const char* name) {
        return spawn([this, name] {
            if (chm_bp_attach_host(path_.c_str(), "holder", nullptr) != 0) return 1;
            chm_rsem_t* mine = open_sem(name);
            if (!mine) return 2;
            stop_at("rsem.v.locked");
            const int r = chm_rsem_v(mine);
            (void)chm_bp_leave();
            return r == 0 ? 0 : 3;
        });
    }
};

// Far above every bound below (20 µs, 10 ms; 5 s for a leave), far below
// the hang, so a slow machine does not fail the test.
constexpr std::uint64_t kAtOnceNs = 2'000'000'000ull;
constexpr std::uint64_t kLeaveNs = 20'000'000'000ull;

std::string last_error() { return chm_bp_last_error(); }

// In a child that forked `c`: wait for it at most 20 s, kill it if it
// hung (never left behind). Its wait status, or -1 when it hung.
int reap_or_kill(pid_t c) {
    int st = 0;
    pid_t r = 0;
    for (int ms = 0; ms < 20000 && (r = waitpid(c, &st, WNOHANG)) == 0; ++ms) sleep_us(1000);
    if (r == c) return st;
    kill(c, SIGKILL);
    waitpid(c, nullptr, 0);
    return -1;
}

// A child attaches, opens the semaphore and stops inside chm_rsem_v
// holding its lock: chm_rsem_try_p gives -EAGAIN naming the holder, a
// timed P -ETIMEDOUT after its own timeout, and a V -EBUSY after 10 ms;
// let go, the child's V lands and ours is not counted twice.
TEST_F(IpcBounds, PAndVReturnWithinTheirBoundsWhileAStalledPeerHoldsTheSemaphoresLock) {
    create();
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), "test", nullptr), 0) << chm_bp_last_error();
    chm_rsem_t* s = make("s", CHM_SEM_COUNTING, 1);
    ASSERT_NE(s, nullptr);
    const pid_t holder = stall_in_v("s");
    ASSERT_TRUE(wait_stopped(holder));

    std::uint64_t t0 = now_ns();
    EXPECT_EQ(chm_rsem_try_p(s), -EAGAIN) << "a unit is free; only the lock is held";
    EXPECT_LT(now_ns() - t0, kAtOnceNs);
    EXPECT_NE(last_error().find("held by slot"), std::string::npos) << last_error();
    t0 = now_ns();
    EXPECT_EQ(chm_rsem_p_timed(s, CHM_NO_WAIT), -EAGAIN);
    EXPECT_LT(now_ns() - t0, kAtOnceNs);
    // A timed P waits for the lock no longer than its own timeout.
    t0 = now_ns();
    EXPECT_EQ(chm_rsem_p_timed(s, 100'000'000), -ETIMEDOUT);
    EXPECT_LT(now_ns() - t0, kAtOnceNs);
    EXPECT_NE(last_error().find("past the call's timeout"), std::string::npos) << last_error();
    t0 = now_ns();
    EXPECT_EQ(chm_rsem_p_until(s, chm_time_now() + 100'000'000), -ETIMEDOUT);
    EXPECT_LT(now_ns() - t0, kAtOnceNs);
    t0 = now_ns();
    EXPECT_EQ(chm_rsem_v(s), -EBUSY);
    EXPECT_LT(now_ns() - t0, kAtOnceNs);
    EXPECT_NE(last_error().find("the unit was not given"), std::string::npos) << last_error();

    kill(holder, SIGCONT);
    EXPECT_EQ(reap(holder), 0);
    EXPECT_EQ(chm_rsem_value(s), 2) << "the initial unit and the holder's V; the refused V gave none";
    EXPECT_EQ(chm_rsem_try_p(s), 0);
    EXPECT_EQ(check_now(), "");
}

// The same for a message queue: a child stopped inside chm_msgq_send
// holding the queue's lock; try_send and try_receive return -EAGAIN at
// once though the queue has both room and a message, and timed calls
// -ETIMEDOUT after their own timeout.
TEST_F(IpcBounds, SendAndReceiveReturnWithinTheirBoundsWhileAStalledPeerHoldsTheQueuesLock) {
    create();
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), "test", nullptr), 0) << chm_bp_last_error();
    chm_msgq_attr_t a;
    chm_msgq_attr_init(&a);
    a.max_msg = 16;
    a.max_count = 4;
    chm_msgq_t* q = nullptr;
    ASSERT_EQ(chm_msgq_create("q", &a, CHM_MSGQ_COMMON, &q), 0) << chm_bp_last_error();
    ASSERT_EQ(chm_msgq_try_send(q, 1, 0, "first", 5), 0);
    const pid_t holder = spawn([&] {
        if (chm_bp_attach_host(path_.c_str(), "holder", nullptr) != 0) return 1;
        chm_msgq_t* mine = nullptr;
        if (chm_msgq_open("q", &mine) != 0) return 2;
        stop_at("msgq.run.locked");
        const int r = chm_msgq_send(mine, 2, 0, "second", 6);
        (void)chm_bp_leave();
        return r == 0 ? 0 : 3;
    });
    ASSERT_TRUE(wait_stopped(holder));

    char buf[16];
    std::uint64_t t0 = now_ns();
    EXPECT_EQ(chm_msgq_try_send(q, 3, 0, "third", 5), -EAGAIN) << "there is room; only the lock is held";
    EXPECT_LT(now_ns() - t0, kAtOnceNs);
    EXPECT_NE(last_error().find("held by slot"), std::string::npos) << last_error();
    t0 = now_ns();
    EXPECT_EQ(chm_msgq_try_receive(q, buf, sizeof buf, nullptr), -EAGAIN) << "a message is queued";
    EXPECT_LT(now_ns() - t0, kAtOnceNs);
    t0 = now_ns();
    EXPECT_EQ(chm_msgq_receive_timed(q, buf, sizeof buf, nullptr, CHM_NO_WAIT), -EAGAIN);
    EXPECT_LT(now_ns() - t0, kAtOnceNs);
    // A timed call waits for the lock no longer than its own timeout.
    t0 = now_ns();
    EXPECT_EQ(chm_msgq_send_timed(q, 3, 0, "third", 5, 100'000'000), -ETIMEDOUT);
    EXPECT_LT(now_ns() - t0, kAtOnceNs);
    EXPECT_NE(last_error().find("past the call's timeout"), std::string::npos) << last_error();
    t0 = now_ns();
    EXPECT_EQ(chm_msgq_receive_until(q, buf, sizeof buf, nullptr, chm_time_now() + 100'000'000), -ETIMEDOUT);
    EXPECT_LT(now_ns() - t0, kAtOnceNs);

    kill(holder, SIGCONT);
    EXPECT_EQ(reap(holder), 0);
    chm_msgq_msg_info_t info{};
    EXPECT_EQ(chm_msgq_try_receive(q, buf, sizeof buf, &info), 5);
    EXPECT_EQ(info.type, 1u);
    EXPECT_EQ(chm_msgq_try_receive(q, buf, sizeof buf, &info), 6);
    EXPECT_EQ(info.type, 2u);
    EXPECT_EQ(chm_msgq_try_receive(q, buf, sizeof buf, nullptr), -EAGAIN) << "the refused send queued nothing";
    EXPECT_EQ(check_now(), "");
}

// An interrupt handler runs with the mask held: nothing else of its RTPU
// runs while it spins. Its V on a semaphore whose lock a stalled peer
// holds gives -EBUSY after the try bound, and a P, whose lock wait is
// bounded at 5 s elsewhere, gives up as soon; before, each spun 5 s
// (then -EDEADLK) with every task and interrupt of the RTPU held up.
chm_rsem_t* g_sem = nullptr;
int g_irq_result = 0;
std::uint64_t g_irq_ns = 0;
std::string g_irq_text;

std::uint64_t g_irq_value_ns = 0;

void v_from_handler(int, void*) {
    std::uint64_t t0 = now_ns();
    g_irq_result = chm_rsem_v(g_sem);
    g_irq_ns = now_ns() - t0;
    g_irq_text = chm_bp_last_error();
    t0 = now_ns();
    (void)chm_rsem_p_timed(g_sem, 1'000'000);  // its lock wait is bounded at 5 s elsewhere
    g_irq_value_ns = now_ns() - t0;
}

void raise_once(void*) {
    if (chm_irq_install(CHM_IRQ_LINE_FIRST, v_from_handler, nullptr) == 0) (void)chm_irq_raise(CHM_IRQ_LINE_FIRST);
}

TEST_F(IpcBounds, AnInterruptHandlersVDoesNotSpinOnAStalledPeersLock) {
    create();
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), "test", nullptr), 0) << chm_bp_last_error();
    chm_rsem_t* s = make("s", CHM_SEM_COUNTING, 0);
    ASSERT_NE(s, nullptr);
    const pid_t holder = stall_in_v("s");
    ASSERT_TRUE(wait_stopped(holder));
    Pipe said;
    const pid_t rtpu = spawn([&] {
        const int r = run_rtpu(path_, 2, [&] {
            g_sem = open_sem("s");
            return g_sem && spawn_task(raise_once, nullptr, "raiser", 1) != CHM_TID_NONE;
        });
        said.put(g_irq_result == -EBUSY ? 'B' : g_irq_result == -EDEADLK ? 'D' : g_irq_result == 0 ? '0' : 'x');
        said.put(g_irq_ns < kAtOnceNs ? 'f' : 's');
        said.put(g_irq_text.find("interrupts masked") != std::string::npos ? 'm' : '?');
        said.put(g_irq_value_ns < kAtOnceNs ? 'f' : 's');
        return r;
    });
    EXPECT_EQ(said.get(20000), 'B') << "the handler's V";
    EXPECT_EQ(said.get(), 'f') << "the handler spun past " << kAtOnceNs << " ns";
    EXPECT_EQ(said.get(), 'm') << "the error text says why it did not wait";
    EXPECT_EQ(said.get(), 'f') << "a P in the handler spun for its 5 s lock bound";
    EXPECT_EQ(reap(rtpu), 0);
    kill(holder, SIGCONT);
    EXPECT_EQ(reap(holder), 0);
    EXPECT_EQ(chm_rsem_value(s), 1) << "the holder's V only";
    EXPECT_EQ(check_now(), "");
}

// A holder stops holding the registry lock; a peer dies; a third process
// attaches, sees its monitor start the dead peer's recovery (which needs
// the registry) and then ends its attachment by `how`. Before the bounds
// the monitor waited for the registry for ever, and chm_bp_leave (exit's
// handler) and fork, which stop the monitor and wait for it, never
// returned.
void IpcBounds::ends_while_the_monitor_waits(Ending how) {
    create();
    const std::string& path = path_;
    Pipe holder_ready, doomed_ready, said;
    const pid_t holder = spawn([&] {
        if (chm_bp_attach_host(path.c_str(), "holder", nullptr) != 0) return 1;
        holder_ready.put('r');
        stop_at("bp.registry.locked");
        chm_rsem_t* none = nullptr;
        (void)chm_rsem_open("none", &none);  // stops holding the registry
        (void)chm_bp_leave();
        return 0;
    });
    ASSERT_EQ(holder_ready.get(), 'r');
    ASSERT_TRUE(wait_stopped(holder));
    const pid_t doomed = spawn([&] {
        if (chm_bp_attach_host(path.c_str(), "doomed", nullptr) != 0) return 1;
        doomed_ready.put(char('0' + chm_bp_self()));
        pause();
        return 0;
    });
    const int dslot = doomed_ready.get() - '0';
    ASSERT_GT(dslot, 0);
    const pid_t ender = spawn([&] {
        if (chm_bp_attach_host(path.c_str(), "ender", nullptr) != 0) return 1;
        said.put('a');
        // This process is the only running survivor: its monitor finds
        // the death and starts the recovery, which needs the registry.
        const std::uint64_t end = now_ns() + 10'000'000'000ull;
        chm_bp_status_t st;
        while (chm_bp_status(&st) == 0 && st.slot[dslot].state != CHM_BP_RECOVERING && now_ns() < end)
            sleep_us(1000);
        if (st.slot[dslot].state != CHM_BP_RECOVERING) return said.put('n'), 2;
        sleep_us(50000);  // well inside the recovery's wait
        said.put('w');
        switch (how) {
        case Ending::kLeave:
            said.put(chm_bp_leave() == 0 ? 'L' : 'x');
            return 0;
        case Ending::kExit:
            std::exit(0);  // its handler leaves
        case Ending::kFork: {
            const pid_t c = fork();
            if (c == 0) _exit(0);
            said.put(c > 0 && reap_or_kill(c) != -1 ? 'F' : 'x');
            return 0;  // not left: a death, recovered by the survivors
        }
        }
        return 3;
    });
    ASSERT_EQ(said.get(), 'a');
    kill9(doomed);
    ASSERT_EQ(said.get(15000), 'w') << "the recovery never started";
    const std::uint64_t t0 = now_ns();
    if (how == Ending::kExit) {
        EXPECT_EQ(reap(ender, int(kLeaveNs / 1000000)), 0) << "exit did not return";
    } else {
        EXPECT_EQ(said.get(int(kLeaveNs / 1000000)), how == Ending::kLeave ? 'L' : 'F') << "it hung";
        EXPECT_EQ(reap(ender), 0);
    }
    EXPECT_LT(now_ns() - t0, kLeaveNs);

    // Let the holder go: the recovery then completes (the holder's monitor,
    // or ours) and the backplane is consistent.
    kill(holder, SIGCONT);
    EXPECT_EQ(reap(holder), 0);
    ASSERT_EQ(chm_bp_attach_host(path.c_str(), "judge", nullptr), 0) << chm_bp_last_error();
    const std::uint64_t end = now_ns() + 20'000'000'000ull;
    chm_bp_status_t st;
    bool settled = false;
    while (!settled && now_ns() < end) {
        settled = chm_bp_status(&st) == 0;
        for (std::uint32_t s = 1; settled && s < st.slots; ++s)
            settled = st.slot[s].state != CHM_BP_RECOVERING && (st.slot[s].state != CHM_BP_RUNNING || int(s) == st.self);
        if (!settled) sleep_us(1000);
    }
    EXPECT_TRUE(settled) << "a dead slot was never recovered";
    EXPECT_EQ(check_now(), "");
}

TEST_F(IpcBounds, LeaveReturnsWhileTheMonitorWaitsForAStalledHolder) {
    ends_while_the_monitor_waits(Ending::kLeave);
}

TEST_F(IpcBounds, ExitReturnsWhileTheMonitorWaitsForAStalledHolder) {
    ends_while_the_monitor_waits(Ending::kExit);
}

TEST_F(IpcBounds, ForkReturnsWhileTheMonitorWaitsForAStalledHolder) {
    ends_while_the_monitor_waits(Ending::kFork);
}

// fork() stops the monitor thread and joins it. Under qemu-user the join
// returns before the thread's emulator side has finished exiting (glib's
// per-thread cache is given back under its lock then); a fork in that
// window copied that lock held, and the child hung in its first
// instructions (the test above, 1 run in 16 under load). So the fork
// waits until the OS no longer has the thread: at the instant of every
// fork the attached process has the threads it had before it attached
// (the caller, and under qemu the emulator's own).
std::set<std::string> os_threads() {
    std::set<std::string> tids;
    if (DIR* d = opendir("/proc/self/task")) {
        while (const dirent* e = readdir(d))
            if (e->d_name[0] != '.') tids.insert(e->d_name);
        closedir(d);
    }
    return tids;
}
std::set<std::string> g_threads_at_fork;
bool g_watch_forks = false;
// Registered at program start, before any attachment registers its own
// handlers, so it runs after them (prepare handlers run in reverse order
// of registration): it sees the process as fork copies it.
[[gnu::constructor]] void watch_forks() {
    pthread_atfork([] { if (g_watch_forks) g_threads_at_fork = os_threads(); }, nullptr, nullptr);
}
TEST_F(IpcBounds, AForkOfAnAttachedProcessCopiesOnlyTheForkingThread) {
    create();
    const std::string& path = path_;
    const pid_t forker = spawn([&] {
        g_watch_forks = true;
        const std::set<std::string> before = os_threads();
        if (chm_bp_attach_host(path.c_str(), "forker", nullptr) != 0) return 1;
        if (os_threads().size() <= before.size()) return 2;  // the monitor runs
        for (int i = 0; i < 50; ++i) {
            const pid_t c = fork();
            if (c == 0) _exit(7);
            if (c < 0) return 3;
            if (reap_or_kill(c) == -1) return 4;
            if (g_threads_at_fork != before) return 10;
        }
        return chm_bp_leave() == 0 ? 0 : 5;
    });
    EXPECT_EQ(reap(forker), 0) << "4: a child hung; 10: another thread existed at a fork";
}

}  // namespace
}  // namespace chm::test
