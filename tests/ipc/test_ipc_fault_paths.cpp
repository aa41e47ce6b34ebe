// Containment along the real paths, without a fault point (issue 15 item
// 1; the fault-injection matrix is test_ipc_fault.cpp): a task parked in a
// backplane wait destroyed by another task and by express mail; a
// deadline handler's abort-cycle delivered at a wait; a processor
// exception inside a call that returns to an error mark; a real bad user
// buffer, which faults before the queue is locked.
#include <cstdint>
#include <cstdio>
#include <vector>

#include "chimera/err.h"
#include "chimera/rsem.h"
#include "chimera/rtpu.h"
#include "chimera/shm.h"
#include "chimera/spin.h"
#include "ipc/backplane/stop_point.hpp"
#include "ipc/msgq/msgq.hpp"
#include "ipc/xmail/xmail.hpp"
#include "fault_fixture.hpp"

namespace chm::test {
namespace {

chm_msgq_t* g_q;
chm_rsem_t* g_s;

class IpcFaultPaths : public FaultTest {
protected:
    // RTPU 1 in a forked child, "fq" open in g_q (and "fs" in g_s with
    // `sem`), running one task `fn`: the child's exit status once its
    // kernel stopped.
    int run_one_task(void (*fn)(void*), const char* name, int prio, bool sem = false) {
        const std::string path = path_;
        const pid_t child = spawn([path, fn, name, prio, sem] {
            return run_rtpu(path, 1, [fn, name, prio, sem] {
                if (chm_msgq_open("fq", &g_q) || (sem && chm_rsem_open("fs", &g_s))) _exit(101);
                spawn_task(fn, nullptr, name, prio, 0);
            });
        });
        return reap(child);
    }
};

}  // namespace
}  // namespace chm::test

namespace chm::test {
namespace {

// Destroy from outside, the way it happens: a task parked in a backplane
// wait is destroyed by another task of its RTPU (a remote semaphore's P)
// and by express mail from another process (a queue's receive). Each
// wait is cancelled, the task ends at once, its record is withdrawn, and
// the unit or message that comes next is not absorbed by it.
struct Remote {
    std::atomic<chm_tid_t> receiver{CHM_TID_NONE};
    std::atomic<int> local_ok{0}, stop{0};
    char failure[300];
};
Remote* g_remote;

void parked_receiver(void*) {
    std::uint32_t v;
    (void)chm_msgq_receive(g_q, &v, sizeof v, nullptr);
    std::snprintf(g_remote->failure, sizeof g_remote->failure, "the receive returned: the task was not destroyed");
}
void parked_p(void*) {
    (void)chm_rsem_p(g_s);
    std::snprintf(g_remote->failure, sizeof g_remote->failure, "P returned: the task was not destroyed");
}

void destroyer(void*) {
    auto fail_with = [](const char* what) {
        std::snprintf(g_remote->failure, sizeof g_remote->failure, "local destroy: %s", what);
        chm_kernel_stop(1);
    };
    chm_task_attr_t at;
    chm_task_attr_init(&at);
    at.name = "p";
    at.priority = 30;
    at.joinable = 1;
    chm_tid_t p = CHM_TID_NONE;
    if (chm_task_spawn(&p, parked_p, nullptr, &at) != 0) fail_with("spawn");
    for (int i = 0; i < 30000 && chm_rsem_waiting(g_s) != 1; ++i) chm_task_pause_until(chm_time_now() + 1'000'000);
    if (chm_rsem_waiting(g_s) != 1) fail_with("P never waited");
    if (chm_task_destroy(p) != 0) fail_with("chm_task_destroy");
    chm_task_status_t st;
    if (chm_task_join(p, 30'000'000'000ull, &st) != 0 || st.end_reason != CHM_TASK_DESTROYED)
        fail_with("the task did not end within 30 s of its destroy");
    if (chm_rsem_waiting(g_s) != 0) fail_with("its record still waits");
    if (chm_rsem_v(g_s) != 0 || chm_rsem_try_p(g_s) != 0) fail_with("the unit after it was absorbed");
    g_remote->local_ok = 1;
    // Then the receiver the parent destroys by express mail.
    at.name = "receiver";
    chm_tid_t r = CHM_TID_NONE;
    if (chm_task_spawn(&r, parked_receiver, nullptr, &at) != 0) fail_with("spawn");
    g_remote->receiver = r;
    while (!g_remote->stop) chm_task_pause_until(chm_time_now() + 1'000'000);
    chm_kernel_stop(0);
}

TEST_F(IpcFaultPaths, ATaskParkedInACallIsDestroyedAtOnceLocallyAndByExpressMail) {
    SharedBlock<Remote> shared;
    Remote* rm = shared.get();
    ASSERT_NE(rm, nullptr);
    g_remote = rm;
    chm_msgq_t* q = nullptr;
    ASSERT_NO_FATAL_FAILURE(attach_with_queue(&q, true));  // the RTPU child serves express mail
    chm_rsem_t* s = nullptr;
    ASSERT_NO_FATAL_FAILURE(make_sem(&s));
    const std::string path = path_;
    const pid_t child = spawn([path] {
        return run_rtpu(path, 1, [] {
            if (chm_msgq_open("fq", &g_q) || chm_rsem_open("fs", &g_s)) _exit(101);
            if (xmail::server_start(50) != 0) _exit(102);
            spawn_task(destroyer, nullptr, "destroyer", 10, 0);
        });
    });
    ASSERT_TRUE(wait_for([&] {
        return rm->failure[0] || (rm->receiver.load() != CHM_TID_NONE && info(q).receivers_waiting == 1);
    }, 60000)) << rm->failure;
    ASSERT_STREQ(rm->failure, "");
    EXPECT_EQ(rm->local_ok.load(), 1) << rm->failure;
    const std::uint64_t t0 = now_ns();
    ASSERT_EQ(chm_rtpu_destroy(1, rm->receiver.load()), 0) << chm_rtpu_last_error();
    ASSERT_TRUE(wait_for([&] { return info(q).receivers_waiting == 0; }, 30000)) << "its record still waits";
    const double us = double(now_ns() - t0) / 1e3;
    std::printf("destroy by express mail of a task parked in a receive -> its record gone: %.0f us\n", us);
    // The next message is not absorbed by the destroyed receiver's record.
    // A send that may wait for the lock: the count read above (without the
    // lock) drops while the RTPU that withdraws the record still holds it
    // for its last few instructions, past a try call's 20 us under qemu.
    const std::uint32_t v = 7;
    ASSERT_EQ(chm_msgq_send_timed(q, 0, 0, &v, sizeof v, 5'000'000'000ull), 0) << chm_err_last();
    std::uint32_t got = 0;
    ASSERT_EQ(chm_msgq_try_receive(q, &got, sizeof got, nullptr), int(sizeof got));
    EXPECT_EQ(got, v);
    EXPECT_EQ(check_now(), "");
    rm->stop = 1;
    EXPECT_EQ(reap(child), 0) << rm->failure;
    EXPECT_STREQ(rm->failure, "");
}

}  // namespace
}  // namespace chm::test

namespace chm::test {
namespace {

// A deadline handler's abort-cycle for a task parked in a receive: the
// miss comes while it waits; when the message arrives the handler runs
// at the wait, the receive completes (the message is in the task's
// buffer, exactly once), and only then does the cycle restart. No record
// is left and the queue is empty.
struct Cycle {
    std::atomic<int> entries{0}, handled{0};
};
Cycle* g_cycle;

chm_deadline_action abort_it(const chm_deadline_info_t*, void*) {
    ++g_cycle->handled;
    return CHM_DL_ABORT_CYCLE;
}

void late_receiver(void*) {
    if (g_cycle->entries.fetch_add(1) > 0) return;  // restarted: done
    // The cycle restarts when this returns: nothing after it runs.
    std::uint32_t v = 0;
    (void)chm_msgq_receive(g_q, &v, sizeof v, nullptr);
}

TEST_F(IpcFaultPaths, ADeadlineHandlersAbortCycleAtAWaitLetsTheCallCompleteFirst) {
    SharedBlock<Cycle> shared;
    Cycle* cy = shared.get();
    ASSERT_NE(cy, nullptr);
    g_cycle = cy;
    chm_msgq_t* q = nullptr;
    ASSERT_NO_FATAL_FAILURE(attach_with_queue(&q));
    const std::string path = path_;
    const pid_t child = spawn([path] {
        return run_rtpu(path, 1, [] {
            if (chm_msgq_open("fq", &g_q)) _exit(101);
            chm_task_attr_t at;
            chm_task_attr_init(&at);
            at.name = "late";
            at.priority = 20;
            // The deadline (100 ms: generous, the task parks long before it
            // on any machine) passes while the task waits; the restart
            // comes at the next release.
            at.period_ns = 400'000'000;
            at.deadline_ns = 100'000'000;
            at.on_deadline = abort_it;
            chm_tid_t t = CHM_TID_NONE;
            if (chm_task_spawn(&t, late_receiver, nullptr, &at) != 0) _exit(102);
            spawn_task([](void*) {
                // Stop once the restarted entry has returned.
                for (int i = 0; i < 60000 && g_cycle->entries.load() < 2; ++i)
                    chm_task_pause_until(chm_time_now() + 1'000'000);
                chm_task_pause_until(chm_time_now() + 5'000'000);
                chm_kernel_stop(0);
            }, nullptr, "stopper", 5, 0);
        });
    });
    ASSERT_TRUE(wait_for([&] { return info(q).receivers_waiting == 1; }, 60000));
    sleep_us(300'000);  // its deadline (100 ms after its release) passes while it waits
    const std::uint32_t v = 42;
    // Not a try call: the lock may still be held by the receiver's RTPU on
    // a slow (emulated) machine.
    ASSERT_EQ(chm_msgq_send_timed(q, 0, 0, &v, sizeof v, 5'000'000'000ull), 0) << chm_err_last();
    EXPECT_EQ(reap(child), 0);
    EXPECT_EQ(cy->entries.load(), 2) << "the cycle was not restarted";
    EXPECT_GE(cy->handled.load(), 1) << "no deadline miss was handled";
    const chm_msgq_info_t in = info(q);
    EXPECT_EQ(in.count, 0u) << "the message was not received";
    EXPECT_EQ(in.received, 1u);
    EXPECT_EQ(in.receivers_waiting, 0u);
    EXPECT_EQ(check_now(), "");
}

}  // namespace
}  // namespace chm::test

namespace chm::test {
namespace {

// A processor exception inside a send (at msgq.send.copy, where a bad user
// buffer would fault) whose handler returns to an error mark set before
// the call: the jump leaves the call's frames, so the queue lock they held
// is given back; the same task's next send works at once and the queue
// holds exactly that message.
struct Marked {
    std::atomic<int> result{-1000};
    std::atomic<int> jumped{0};
    std::atomic<std::uint64_t> next_ns{0};
};
Marked* g_marked;

chm_err_action_t to_mark(const chm_err_info_t*, void*) { return CHM_ERR_TO_MARK; }

void marked_sender(void*) {
    if (chm_err_on_task(to_mark, nullptr) != 0) return;
    static chm_err_mark_t m;  // static: read after the jump
    if (chm_err_mark(&m) == 0) {
        setenv("CHIMERA_FAULT_AT", "msgq.send.copy:fault", 1);
        stop::reload();
        const std::uint32_t one = 1;
        (void)chm_msgq_send(g_q, 0, 0, &one, sizeof one);  // faults, returns to the mark
        (void)chm_err_unmark(&m);
        chm_kernel_stop(0);
        return;
    }
    unsetenv("CHIMERA_FAULT_AT");
    stop::reload();
    g_marked->jumped = 1;
    (void)chm_err_unmark(&m);
    const std::uint32_t two = 2;
    const std::uint64_t t0 = chm_time_now();
    g_marked->result = chm_msgq_try_send(g_q, 0, 0, &two, sizeof two);
    g_marked->next_ns = chm_time_now() - t0;
    chm_kernel_stop(0);
}

TEST_F(IpcFaultPaths, AReturnToAnErrorMarkFromInsideACallGivesItsLockBack) {
    SharedBlock<Marked> shared;
    Marked* mk = shared.get();
    ASSERT_NE(mk, nullptr);
    g_marked = mk;
    chm_msgq_t* q = nullptr;
    ASSERT_NO_FATAL_FAILURE(attach_with_queue(&q));
    EXPECT_EQ(run_one_task(marked_sender, "marked", 20), 0);
    EXPECT_EQ(mk->jumped.load(), 1) << "the fault did not return to the mark";
    EXPECT_EQ(mk->result.load(), 0) << "the task's next send after the jump";
    std::printf("the next send after the jump: %.1f us\n", double(mk->next_ns.load()) / 1e3);
    EXPECT_LT(mk->next_ns.load(), 500'000'000ull);  // far below the 5 s -EDEADLK
    std::vector<std::uint32_t> got;
    for (std::uint32_t x; chm_msgq_try_receive(q, &x, sizeof x, nullptr) == int(sizeof x);) got.push_back(x);
    EXPECT_EQ(got, std::vector<std::uint32_t>{2});
    EXPECT_EQ(check_now(), "");
}

}  // namespace
}  // namespace chm::test

namespace chm::test {
namespace {

// A real bad buffer, no fault point: a send from an unmapped page and a
// receive into a read-only one fault in the caller's task before the
// queue's lock is taken (the buffers are probed first), so the queue is
// never left to repair: its repair count stays 0, the message stays
// queued, and the next send and receive work at once.
struct BadBuf {
    std::atomic<int> jumps{0};
    std::atomic<int> sent{-1000}, received{-1000};
    std::atomic<std::uint32_t> got{0};
};
BadBuf* g_bad;

void bad_buffer_user(void*) {
    if (chm_err_on_task(to_mark, nullptr) != 0) return;
    void* none = mmap(nullptr, 8192, PROT_NONE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    void* ro = mmap(nullptr, 8192, PROT_READ, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (none == MAP_FAILED || ro == MAP_FAILED) return chm_kernel_stop(1);
    static chm_err_mark_t m;  // static: read after the jump
    if (chm_err_mark(&m) == 0) (void)chm_msgq_send(g_q, 0, 0, none, 4);  // faults, to the mark
    (void)chm_err_unmark(&m);
    ++g_bad->jumps;
    const std::uint32_t one = 1;
    g_bad->sent = chm_msgq_try_send(g_q, 0, 0, &one, sizeof one);
    if (chm_err_mark(&m) == 0) (void)chm_msgq_receive(g_q, ro, 4, nullptr);  // faults, to the mark
    (void)chm_err_unmark(&m);
    ++g_bad->jumps;
    std::uint32_t v = 0;
    g_bad->received = chm_msgq_try_receive(g_q, &v, sizeof v, nullptr);
    g_bad->got = v;
    chm_kernel_stop(0);
}

TEST_F(IpcFaultPaths, ABadUserBufferFaultsBeforeTheQueueIsLocked) {
    SharedBlock<BadBuf> shared;
    BadBuf* bb = shared.get();
    ASSERT_NE(bb, nullptr);
    g_bad = bb;
    chm_msgq_t* q = nullptr;
    ASSERT_NO_FATAL_FAILURE(attach_with_queue(&q));
    EXPECT_EQ(run_one_task(bad_buffer_user, "badbuf", 20), 0);
    EXPECT_EQ(bb->jumps.load(), 2) << "both calls faulted back to the mark";
    EXPECT_EQ(bb->sent.load(), 0);
    EXPECT_EQ(bb->received.load(), int(sizeof(std::uint32_t)));
    EXPECT_EQ(bb->got.load(), 1u) << "the receive that faulted took no message";
    EXPECT_EQ(reinterpret_cast<ipc::msgq::QueueHeader*>(q)->repairs.load(), 0u)
        << "the queue was locked when the task faulted, and rebuilt by its next user";
    chm_msgq_info_t info;
    ASSERT_EQ(chm_msgq_info(q, &info), 0);
    EXPECT_EQ(info.count, 0u);
    EXPECT_EQ(check_now(), "");
}

}  // namespace
}  // namespace chm::test

namespace chm::test {
namespace {

// A task destroyed inside a call ends when the call returns. An end hook
// of its that makes a backplane call of its own must not carry that owed
// end out again from inside the hook: before, the hook's call ended the
// task a second time as it returned, and the rest of the hook never ran.
struct Hooked {
    std::atomic<int> runs{0}, finished{0};
    std::atomic<int> end_reason{-1};
    std::atomic<int> units{-1000};
};
Hooked* g_hooked;

void end_hook(void*) {
    ++g_hooked->runs;
    (void)chm_rsem_v(g_s);  // a call scope of its own
    ++g_hooked->finished;
}
void hooked_victim(void*) {
    if (chm_task_on_end(end_hook, nullptr) != 0) return;
    setenv("CHIMERA_FAULT_AT", "msgq.send.copy:destroy", 1);
    stop::reload();
    const std::uint32_t one = 1;
    (void)chm_msgq_send(g_q, 0, 0, &one, sizeof one);  // destroyed, owed to the return
}
void hooked_driver(void*) {
    chm_task_attr_t at;
    chm_task_attr_init(&at);
    at.name = "victim";
    at.priority = 20;
    at.joinable = 1;
    chm_tid_t v = CHM_TID_NONE;
    chm_task_status_t st;
    if (chm_task_spawn(&v, hooked_victim, nullptr, &at) == 0 && chm_task_join(v, 30'000'000'000ull, &st) == 0)
        g_hooked->end_reason = int(st.end_reason);
    unsetenv("CHIMERA_FAULT_AT");
    stop::reload();
    g_hooked->units = chm_rsem_value(g_s);
    chm_kernel_stop(0);
}

TEST_F(IpcFaultPaths, AnEndHooksOwnCallDoesNotEndTheTaskAgain) {
    SharedBlock<Hooked> shared;
    Hooked* h = shared.get();
    ASSERT_NE(h, nullptr);
    g_hooked = h;
    chm_msgq_t* q = nullptr;
    ASSERT_NO_FATAL_FAILURE(attach_with_queue(&q));
    chm_rsem_t* s = nullptr;
    ASSERT_NO_FATAL_FAILURE(make_sem(&s));
    EXPECT_EQ(run_one_task(hooked_driver, "driver", 10, true), 0);
    EXPECT_EQ(h->end_reason.load(), int(CHM_TASK_DESTROYED));
    EXPECT_EQ(h->runs.load(), 1) << "the end hook ran more than once";
    EXPECT_EQ(h->finished.load(), 1) << "the end hook was cut short at its own call's return";
    EXPECT_EQ(h->units.load(), 1) << "the hook's one V";
    std::uint32_t x = 0;
    EXPECT_EQ(chm_msgq_try_receive(q, &x, sizeof x, nullptr), int(sizeof x)) << "the send completed before the end";
    EXPECT_EQ(check_now(), "");
}

}  // namespace
}  // namespace chm::test

namespace chm::test {
namespace {

// A user spin-lock taken by one task and unlocked by another (allowed: the
// lock is the RTPU's) leaves a stale entry on the taker's hold list; ten
// rounds of that, then the taker aborts holding a second spin-lock: that
// lock passes on at once, owner-died (the stale entries did not fill the list, so
// it was recorded).
struct Spin {
    chm_spin_t* lock = nullptr;
    chm_spin_t* other = nullptr;
    std::atomic<int> phase{0}, rounds{0}, done{0};
    std::atomic<int> next_user{-1000};
};
Spin* g_spin;

chm_err_action_t quiet(const chm_err_info_t*, void*) { return CHM_ERR_ABORT; }

void spin_taker(void*) {
    (void)chm_err_on_task(quiet, nullptr);
    for (int i = 0; i < 10; ++i) {
        if (chm_spin_lock(g_spin->lock, 1000, 1'000'000'000ull) != 0) return;
        g_spin->phase = 1;  // the other task unlocks it
        while (g_spin->phase.load() != 2) chm_task_pause_until(chm_time_now() + 100'000);
        g_spin->phase = 0;
        ++g_spin->rounds;
    }
    if (chm_spin_lock(g_spin->other, 1000, 1'000'000'000ull) != 0) return;
    (void)chm_err_invoke(CHM_ERR_KERNEL, EFAULT);  // aborts, the second lock held
}

void spin_unlocker(void*) {
    for (int i = 0; i < 10; ++i) {
        while (g_spin->phase.load() != 1) chm_task_pause_until(chm_time_now() + 100'000);
        (void)chm_spin_unlock(g_spin->lock);
        g_spin->phase = 2;
    }
    chm_task_pause_until(chm_time_now() + 5'000'000);  // the taker aborts meanwhile
    g_spin->next_user = chm_spin_try_lock(g_spin->other);
    if (g_spin->next_user == 0 || g_spin->next_user == -EOWNERDEAD) (void)chm_spin_unlock(g_spin->other);
    chm_kernel_stop(0);
}

TEST_F(IpcFaultPaths, AUserSpinLockUnlockedByAnotherTaskLeavesNoStaleHold) {
    SharedBlock<Spin> shared;
    Spin* sp = shared.get();
    ASSERT_NE(sp, nullptr);
    g_spin = sp;
    create();
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0);
    void* mem = nullptr;
    ASSERT_EQ(chm_shm_create("spin", 2 * sizeof(chm_spin_t), CHM_SHM_COMMON, &mem), 0) << chm_bp_last_error();
    ASSERT_EQ(chm_spin_init(static_cast<chm_spin_t*>(mem)), 0);
    ASSERT_EQ(chm_spin_init(static_cast<chm_spin_t*>(mem) + 1), 0);
    const std::string path = path_;
    const pid_t child = spawn([path] {
        return run_rtpu(path, 1, [] {
            void* m = nullptr;
            if (chm_shm_attach("spin", &m, nullptr)) _exit(101);
            g_spin->lock = static_cast<chm_spin_t*>(m);
            g_spin->other = g_spin->lock + 1;
            spawn_task(spin_taker, nullptr, "taker", 20, 0);
            spawn_task(spin_unlocker, nullptr, "unlocker", 10, 0);
        });
    });
    EXPECT_EQ(reap(child), 0);
    EXPECT_EQ(sp->rounds.load(), 10);
    // Taken at once, and told its holder ended with it (the data it
    // guards may be half changed): a user's spin-lock passes on owner-died.
    EXPECT_EQ(sp->next_user.load(), -EOWNERDEAD) << "the aborted task's second spin-lock was not passed on";
    EXPECT_EQ(check_now(), "");
}

}  // namespace
}  // namespace chm::test
