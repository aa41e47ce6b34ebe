// Local semaphores, user signals, deadline-failure handling and CPU lock,
// on the virtual clock.
#include <cerrno>

#include "kernel_fixture.hpp"
#include "task/holds.hpp"

namespace chm::test {
namespace {

std::string g_log;
chm_sem_t g_sem;

class Sync : public KernelTest {
protected:
    void SetUp() override { g_log.clear(); }
};

void waiter(void* tag) {
    g_log += static_cast<const char*>(tag);
    EXPECT_EQ(chm_sem_p(&g_sem), 0);
    g_log += static_cast<const char*>(tag);
}

void giver(void*) {
    g_log += "V";
    for (int i = 0; i < 3; ++i) EXPECT_EQ(chm_sem_v(&g_sem), 0);
    g_log += "v";
}

TEST_F(Sync, VWakesWaitersMostUrgentFirstAndPreempts) {
    start(CHM_SCHED_FIXED);
    ASSERT_EQ(chm_sem_init(&g_sem, CHM_SEM_COUNTING, 0, 0), 0);
    spawn(waiter, (void*)"a", "a", 3);
    spawn(waiter, (void*)"b", "b", 5);
    spawn(waiter, (void*)"c", "c", 4);
    spawn(giver, nullptr, "giver", 1);
    ASSERT_EQ(chm_kernel_run(), 0);
    // All block in priority order b c a; each V wakes the most urgent
    // waiter, which preempts the low-priority giver at once.
    EXPECT_EQ(g_log, "bcaVbcav");
    EXPECT_EQ(chm_sem_value(&g_sem), 0);
}

void try_and_timeout(void*) {
    EXPECT_EQ(chm_sem_try_p(&g_sem), -EAGAIN);
    const uint64_t t0 = chm_time_now();
    EXPECT_EQ(chm_sem_p_timed(&g_sem, 3 * kMs), -ETIMEDOUT);
    EXPECT_EQ(chm_time_now() - t0, 3 * kMs) << "the timeout is exact on the virtual clock";
    EXPECT_EQ(chm_sem_v(&g_sem), 0);
    EXPECT_EQ(chm_sem_v(&g_sem), -EOVERFLOW) << "binary semaphore already 1";
    EXPECT_EQ(chm_sem_try_p(&g_sem), 0);
    EXPECT_EQ(chm_sem_p_timed(&g_sem, CHM_NO_WAIT), -EAGAIN);
}

TEST_F(Sync, TryPTimeoutAndOverflow) {
    start(CHM_SCHED_MUF);
    ASSERT_EQ(chm_sem_init(&g_sem, CHM_SEM_BINARY, 0, 0), 0);
    spawn(try_and_timeout, nullptr, "t");
    ASSERT_EQ(chm_kernel_run(), 0);
}

TEST_F(Sync, BadSemaphoreArgumentsAreRefused) {
    chm_sem_t s;
    EXPECT_EQ(chm_sem_init(&s, CHM_SEM_BINARY, 2, 0), -EINVAL);
    EXPECT_EQ(chm_sem_init(&s, (chm_sem_kind)7, 0, 0), -EINVAL);
    EXPECT_EQ(chm_sem_init(&s, CHM_SEM_COUNTING, 0, CHM_SEM_INHERIT), -EINVAL);
    EXPECT_EQ(chm_sem_init(&s, CHM_SEM_COUNTING, CHM_SEM_COUNT_MAX + 1u, 0), -EINVAL);
    EXPECT_EQ(chm_sem_init(nullptr, CHM_SEM_BINARY, 0, 0), -EINVAL);
    ASSERT_EQ(chm_sem_init(&s, CHM_SEM_COUNTING, CHM_SEM_COUNT_MAX, 0), 0);
    EXPECT_EQ(chm_sem_v(&s), -EOVERFLOW);
    EXPECT_EQ(chm_sem_destroy(&s), 0);
    EXPECT_EQ(chm_sem_v(&s), -EINVAL) << "destroyed";
}

void destroyed_waiter(void*) { EXPECT_EQ(chm_sem_p(&g_sem), -EIDRM); g_log += "w"; }
void destroyer(void*) { EXPECT_EQ(chm_sem_destroy(&g_sem), 0); g_log += "d"; }

TEST_F(Sync, DestroyWakesWaitersWithEidrm) {
    start(CHM_SCHED_FIXED);
    ASSERT_EQ(chm_sem_init(&g_sem, CHM_SEM_BINARY, 0, 0), 0);
    spawn(destroyed_waiter, nullptr, "w", 5);
    spawn(destroyer, nullptr, "d", 1);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_log, "wd");
}

// Priority inheritance: low takes the mutex, high blocks on it, mid would
// otherwise run in between (unbounded inversion).
chm_sem_t g_mutex;
void pi_low(void*) {
    ASSERT_EQ(chm_sem_p(&g_mutex), 0);
    g_log += "L";
    chm_time_consume(2 * kMs);  // high and mid are released meanwhile
    g_log += "l";
    ASSERT_EQ(chm_sem_v(&g_mutex), 0);
}
void pi_high(void*) {
    chm_task_pause_until(1 * kMs);
    g_log += "H";
    ASSERT_EQ(chm_sem_p(&g_mutex), 0);
    g_log += "h";
    (void)chm_sem_v(&g_mutex);
}
void pi_mid(void*) {
    chm_task_pause_until(1 * kMs);
    g_log += "M";
    chm_time_consume(5 * kMs);
    g_log += "m";
}

TEST_F(Sync, PriorityInheritanceBoundsTheInversion) {
    start(CHM_SCHED_FIXED);
    ASSERT_EQ(chm_sem_init(&g_mutex, CHM_SEM_BINARY, 1, CHM_SEM_INHERIT), 0);
    spawn(pi_low, nullptr, "low", 1);
    spawn(pi_high, nullptr, "high", 9);
    spawn(pi_mid, nullptr, "mid", 5);
    ASSERT_EQ(chm_kernel_run(), 0);
    // With inheritance low finishes its section before mid runs.
    EXPECT_EQ(g_log, "LHlhMm");
}

// ---- user signals
chm_tid_t g_target;
std::string g_handled_by;
void on_sig(int signo, void* arg) {
    g_log += "S" + std::to_string(signo);
    char name[32];
    chm_task_status_t st;
    (void)chm_task_status(chm_task_self(), &st);
    g_handled_by = st.name;
    (void)name;
    (void)arg;
}
void sig_target(void*) {
    ASSERT_EQ(chm_usig_handle(7, on_sig, nullptr), 0);
    EXPECT_EQ(chm_usig_handle(0, on_sig, nullptr), -EINVAL);
    g_log += "P";
    EXPECT_EQ(chm_sem_p(&g_sem), -EINTR) << "a user signal interrupts the wait";
    g_log += "i";
    EXPECT_EQ(chm_task_pause_until(50 * kMs), -EINTR);
    g_log += "j";
}
void sig_sender(void*) {
    chm_time_consume(1 * kMs);
    g_log += ">";
    EXPECT_EQ(chm_usig_send(g_target, 7), 0);
    chm_time_consume(1 * kMs);
    g_log += ">";
    EXPECT_EQ(chm_usig_send(g_target, 7), 0);
    EXPECT_EQ(chm_usig_send(g_target, 32), -EINVAL);
    EXPECT_EQ(chm_usig_send(424242, 3), -ESRCH);
}

TEST_F(Sync, UserSignalRunsInTheTargetAndInterruptsItsWait) {
    start(CHM_SCHED_FIXED);
    ASSERT_EQ(chm_sem_init(&g_sem, CHM_SEM_BINARY, 0, 0), 0);
    g_target = spawn(sig_target, nullptr, "target", 5);
    spawn(sig_sender, nullptr, "sender", 1);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_log, "P>S7i>S7j");
    EXPECT_EQ(g_handled_by, "target");
}

// ---- deadline failures
int g_entries = 0;
chm_deadline_info_t g_info;
chm_deadline_action on_miss(const chm_deadline_info_t* info, void* arg) {
    g_info = *info;
    g_log += "D";
    return static_cast<chm_deadline_action>(reinterpret_cast<intptr_t>(arg));
}
void overrunner(void*) {
    ++g_entries;
    for (;;) {
        g_log += "c";
        // The first cycle overruns its 4 ms deadline; later ones do not.
        chm_time_consume(g_entries == 1 && g_log.size() == 1 ? 6 * kMs : 1 * kMs);
        g_log += "e";
        if (chm_time_now() >= 30 * kMs) return;
        chm_task_wait_period();
    }
}

// A 10 ms task with a 4 ms deadline whose handler decides `action`.
void spawn_with_miss_handler(void (*body)(void*), chm_deadline_action action) {
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = "over";
    a.period_ns = 10 * kMs;
    a.deadline_ns = 4 * kMs;
    a.wcet_ns = 1 * kMs;
    a.on_deadline = on_miss;
    a.on_deadline_arg = reinterpret_cast<void*>(intptr_t(action));
    chm_tid_t id;
    ASSERT_EQ(chm_task_spawn(&id, body, nullptr, &a), 0);
}

TEST_F(Sync, DeadlineHandlerAbortsTheCycleAndTheEntryRestarts) {
    start(CHM_SCHED_MUF);
    g_entries = 0;
    spawn_with_miss_handler(overrunner, CHM_DL_ABORT_CYCLE);
    ASSERT_EQ(chm_kernel_run(), 0);
    // Cycle 0 misses at 4 ms: the handler runs in the task at once, the rest
    // of the cycle is dropped ("e" never printed), the entry restarts at 10.
    EXPECT_EQ(g_log.substr(0, 2), "cD");
    EXPECT_EQ(g_entries, 2);
    EXPECT_EQ(g_info.cycle, 0u);
    EXPECT_EQ(g_info.deadline_ns, 4 * kMs);
    EXPECT_EQ(g_info.now_ns, 4 * kMs + 1) << "the handler runs as soon as the deadline has passed";
    EXPECT_EQ(g_info.misses, 1u);
}

// A cycle aborted from the shallowest frames there are: the entry's only
// call, in tail position, is the abort itself (what a deadline handler's
// or the fault injection's abort-cycle comes to when it is owed to the end
// of a backplane call the entry tail-called). The restart lays the entry
// frame out under the stack's top; it must not keep its own frame or save
// its registers there. On aarch64 it did (the entry frame is 176 bytes, the
// frames above the restart 160): the switch stored the old stack pointer
// over the new frame's argument, and the restarted entry faulted.
int g_shallow_entries = 0;
void* g_shallow_args[2];
void shallow_aborter(void* arg) {
    const int n = g_shallow_entries++;
    if (n < 2) g_shallow_args[n] = arg;
    if (n > 0) return;  // the restarted cycle only ends
    chm::kernel::abort_cycle_current();
}

TEST_F(Sync, ACycleAbortedFromTheShallowestFrameRestartsItsEntry) {
    start(CHM_SCHED_MUF);
    g_shallow_entries = 0;
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = "shallow";
    a.period_ns = 10 * kMs;
    chm_tid_t id;
    static int token;
    ASSERT_EQ(chm_task_spawn(&id, shallow_aborter, &token, &a), 0);
    ASSERT_EQ(chm_kernel_run(), 0);
    ASSERT_EQ(g_shallow_entries, 2) << "the entry restarted once";
    EXPECT_EQ(g_shallow_args[0], &token);
    EXPECT_EQ(g_shallow_args[1], &token) << "the restarted entry has its argument";
    chm_task_status_t st;
    ASSERT_EQ(chm_task_status(id, &st), 0);
    EXPECT_EQ(st.end_reason, CHM_TASK_RETURNED) << "it returned, not faulted";
}

TEST_F(Sync, DeadlineHandlerMayLetTheCycleContinue) {
    start(CHM_SCHED_MUF);
    g_entries = 0;
    spawn_with_miss_handler(overrunner, CHM_DL_CONTINUE);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_log.substr(0, 3), "cDe");
    EXPECT_EQ(g_entries, 1);
}

bool g_hook_ran = false;
void shutdown_hook(void*) { g_hook_ran = true; }
void stopper_body(void*) {
    (void)chm_kernel_on_shutdown(shutdown_hook, nullptr);
    chm_time_consume(6 * kMs);
    ADD_FAILURE() << "the RTPU should have stopped at the deadline";
}

TEST_F(Sync, DeadlineHandlerMayStopTheRtpuGracefully) {
    start(CHM_SCHED_MUF);
    g_hook_ran = false;
    spawn_with_miss_handler(stopper_body, CHM_DL_STOP_RTPU);
    EXPECT_EQ(chm_kernel_run(), 0);
    EXPECT_TRUE(g_hook_ran);
    EXPECT_EQ(chm_time_now(), 4 * kMs + 1);
}

// A hook that blocks: the other tasks go on while it waits, and the run
// loop returns only when it is done (a hook that waits for a loop to end
// its cycle, as the loop demo's do, prints final counts).
int g_cycles_after_stop = -1;
int g_cycles = 0;
volatile bool g_stop_asked = false;
bool g_hook_done = false;
void pausing_hook(void*) {
    g_stop_asked = true;
    const int before = g_cycles;
    chm_task_pause_until(chm_time_now() + 5 * kMs);
    g_cycles_after_stop = g_cycles - before;
    g_hook_done = true;
}
void counting_loop(void*) {
    for (;;) {
        ++g_cycles;
        chm_task_wait_period();
    }
}
void stop_at_3ms(void*) {
    chm_task_pause_until(3 * kMs);
    chm_kernel_stop(7);
}

TEST_F(Sync, ShutdownHookMayBlockWhileTheOtherTasksRun) {
    start(CHM_SCHED_MUF);
    g_cycles = 0;
    g_hook_done = false;
    g_cycles_after_stop = -1;
    ASSERT_EQ(chm_kernel_on_shutdown(pausing_hook, nullptr), 0);
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = "loop";
    a.period_ns = 1 * kMs;
    a.wcet_ns = kMs / 10;
    chm_tid_t id;
    ASSERT_EQ(chm_task_spawn(&id, counting_loop, nullptr, &a), 0);
    spawn(stop_at_3ms, nullptr, "stopper", 50);
    EXPECT_EQ(chm_kernel_run(), 7);
    EXPECT_TRUE(g_hook_done) << "the run loop returned while the hook was paused";
    EXPECT_EQ(g_cycles_after_stop, 5) << "the loop's releases at 4..8 ms ran while the hook waited";
    EXPECT_EQ(chm_time_now(), 8 * kMs);
}

// A hook that calls chm_kernel_stop itself (a handler it triggers asks to
// stop the RTPU): the call returns at once, the stop goes on.
bool g_second_hook_ran = false;
void stopping_hook(void*) {
    chm_kernel_stop(9);
    g_second_hook_ran = true;
}
void stop_now(void*) { chm_kernel_stop(7); }

TEST_F(Sync, AStopFromAShutdownHookReturnsAndTheStopGoesOn) {
    start(CHM_SCHED_FIXED);
    g_second_hook_ran = false;
    ASSERT_EQ(chm_kernel_on_shutdown(stopping_hook, nullptr), 0);
    spawn(stop_now, nullptr, "stopper", 5);
    EXPECT_EQ(chm_kernel_run(), 7) << "the first stop's code; not a hang (-EDEADLK on the virtual clock)";
    EXPECT_TRUE(g_second_hook_ran);
}

// ---- CPU lock
void locked_low(void*) {
    chm_task_lock();
    chm_task_lock();  // nestable
    g_log += "L";
    chm_time_consume(3 * kMs);  // a more urgent task is released at 1 ms
    g_log += "l";
    chm_task_unlock();
    g_log += "n";  // still locked (one level left)
    chm_task_unlock();  // the pending preemption happens here
    g_log += "u";
}
void urgent(void*) { g_log += "U"; }

TEST_F(Sync, LockedTaskIsNotPreemptedUntilItUnlocks) {
    start(CHM_SCHED_FIXED);
    spawn(locked_low, nullptr, "low", 1);
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.priority = 9;
    a.period_ns = 100 * kMs;
    a.start_ns = 1 * kMs;
    chm_tid_t id;
    ASSERT_EQ(chm_task_spawn(&id, urgent, nullptr, &a), 0);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_log, "LlnUu");
}

}  // namespace
}  // namespace chm::test
