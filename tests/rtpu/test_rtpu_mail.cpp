// Express mail between real chimera-rtpu processes and this test (a host
// process): remote spawn, signals, task lists, errors, and what happens
// when a target or a sender dies or stalls.
#include <algorithm>
#include <thread>

#include "ipc/xmail/xmail.hpp"
#include "rtpu_fixture.hpp"

using namespace chm::test;

namespace {

bool has_task(int rtpu, const char* name, chm_tid_t* id = nullptr) {
    chm_rtpu_task_t t[64];
    int total = 0;
    const int n = chm_rtpu_tasks(rtpu, t, 64, &total);
    for (int i = 0; i < n; ++i)
        if (!std::strcmp(t[i].name, name)) {
            if (id) *id = t[i].id;
            return true;
        }
    return false;
}

}  // namespace

TEST_F(RtpuTest, TwoRtpusRunAndAnswer) {
    create();
    const pid_t p1 = start_rtpu(1), p2 = start_rtpu(2, {"--policy", "edf", "--name", "second"});
    ASSERT_TRUE(wait_serving(1, p1)) << read_file(err_of(1));
    ASSERT_TRUE(wait_serving(2, p2)) << read_file(err_of(2));
    chm_bp_status_t st;
    ASSERT_EQ(chm_bp_status(&st), 0);
    EXPECT_EQ(st.slot[1].kind, CHM_BP_KIND_RTPU);
    EXPECT_STREQ(st.slot[1].name, "rtpu1");
    EXPECT_STREQ(st.slot[2].name, "second");
    chm_rtpu_info_t info;
    ASSERT_EQ(chm_rtpu_ping(2, &info), 0);
    EXPECT_EQ(info.pid, p2);
    EXPECT_EQ(info.policy, CHM_SCHED_EDF);
    EXPECT_EQ(info.tasks, 3u);  // the express-mail server, the shutdown task and the stdio drainer
    EXPECT_TRUE(has_task(1, "xmail"));
    EXPECT_TRUE(has_task(2, "shutdown"));
    EXPECT_TRUE(has_task(2, "stdio"));
    EXPECT_NE(read_file(out_of(1)).find("RTPU 1 joined"), std::string::npos);

    // Round trip of a ping from this host thread (printed, not asserted).
    std::vector<std::uint64_t> us;
    for (int i = 0; i < 200; ++i) {
        timespec a{}, b{};
        clock_gettime(CLOCK_MONOTONIC, &a);
        ASSERT_EQ(chm_rtpu_ping(1, nullptr), 0);
        clock_gettime(CLOCK_MONOTONIC, &b);
        us.push_back(std::uint64_t((b.tv_sec - a.tv_sec) * 1000000000LL + (b.tv_nsec - a.tv_nsec)) / 1000);
    }
    std::sort(us.begin(), us.end());
    std::printf("express mail ping, host -> idle RTPU: p50 %llu us, p99 %llu us (200 round trips)\n",
                static_cast<unsigned long long>(us[100]), static_cast<unsigned long long>(us[198]));
}

TEST_F(RtpuTest, RemoteSpawnFromHostRunsMainThereAndSignalsArrive) {
    create();
    const pid_t p2 = start_rtpu(2);
    ASSERT_TRUE(wait_serving(2, p2)) << read_file(err_of(2));
    const std::string file = dir_ + "/probe.txt";
    const char* argv[] = {PROBE_SO, file.c_str()};
    chm_tid_t tid = CHM_TID_NONE;
    ASSERT_EQ(chm_rtpu_spawn(2, PROBE_SO, 2, argv, &tid), 0) << chm_rtpu_last_error();
    EXPECT_GE(tid, 0);
    // Its main runs in RTPU 2's process.
    ASSERT_TRUE(wait_text(file, "main " + std::to_string(p2))) << read_file(file);
    chm_tid_t found = CHM_TID_NONE;
    ASSERT_EQ(chm_rtpu_find(2, "probe.so", &found), 0) << chm_rtpu_last_error();
    EXPECT_EQ(found, tid);
    chm_tid_t listed = CHM_TID_NONE;
    EXPECT_TRUE(has_task(2, "probe.so", &listed));
    EXPECT_EQ(listed, tid);

    // A user signal to the remote task arrives (its handler writes a line).
    ASSERT_EQ(chm_rtpu_signal(2, tid, 5), 0) << chm_rtpu_last_error();
    EXPECT_TRUE(wait_text(file, "signal 5")) << read_file(file);
    ASSERT_EQ(chm_rtpu_signal(2, tid, 17), 0);
    EXPECT_TRUE(wait_text(file, "signal 17")) << read_file(file);
    // Errors come back with their meaning.
    EXPECT_EQ(chm_rtpu_signal(2, tid, 0), -EINVAL);
    EXPECT_EQ(chm_rtpu_signal(2, tid, 32), -EINVAL);
    EXPECT_EQ(chm_rtpu_signal(2, tid + 7, 5), -ESRCH);
    EXPECT_EQ(chm_rtpu_find(2, "no-such-task", &found), -ESRCH);
    chm_tid_t server = CHM_TID_NONE;
    ASSERT_EQ(chm_rtpu_find(2, "xmail", &server), 0);
    EXPECT_EQ(chm_rtpu_destroy(2, server), -EPERM);  // express mail would die with it
    // Destroy the probe remotely: it is gone from the list.
    ASSERT_EQ(chm_rtpu_destroy(2, tid), 0);
    EXPECT_FALSE(has_task(2, "probe.so"));
    EXPECT_EQ(chm_rtpu_signal(2, tid, 5), -ESRCH);
}

TEST_F(RtpuTest, SpawnErrorsNameTheProblem) {
    create();
    const pid_t p1 = start_rtpu(1);
    ASSERT_TRUE(wait_serving(1, p1));
    const std::string missing = dir_ + "/missing.so";
    EXPECT_EQ(chm_rtpu_spawn(1, missing.c_str(), 0, nullptr, nullptr), -ENOENT);
    // The file and the cause, once each.
    EXPECT_EQ(std::string(chm_rtpu_last_error()), "RTPU 1 cannot load " + missing + ": No such file or directory");
    const std::string text = dir_ + "/text.so";
    { std::ofstream(text) << "not an ELF file\n"; }
    EXPECT_EQ(chm_rtpu_spawn(1, text.c_str(), 0, nullptr, nullptr), -ENOEXEC);
    EXPECT_NE(std::string(chm_rtpu_last_error()).find("text.so"), std::string::npos) << chm_rtpu_last_error();
    EXPECT_EQ(chm_rtpu_spawn(1, NOMAIN_SO, 0, nullptr, nullptr), -ENOEXEC);
    EXPECT_EQ(std::string(chm_rtpu_last_error()).rfind(std::string("RTPU 1 cannot load ") + NOMAIN_SO + ": no main", 0),
              0u) << chm_rtpu_last_error();
    EXPECT_EQ(chm_rtpu_spawn(1, nullptr, 0, nullptr, nullptr), -EINVAL);
    EXPECT_EQ(chm_rtpu_spawn(1, PROBE_SO, 1, nullptr, nullptr), -EINVAL);
    // A request that cannot fit one 1 KiB record.
    std::vector<std::string> big(40, std::string(40, 'x'));
    std::vector<const char*> argv;
    for (auto& s : big) argv.push_back(s.c_str());
    EXPECT_EQ(chm_rtpu_spawn(1, PROBE_SO, int(argv.size()), argv.data(), nullptr), -EMSGSIZE);
    // Slots without an RTPU, and out of range.
    EXPECT_EQ(chm_rtpu_ping(3, nullptr), -EHOSTDOWN);
    EXPECT_NE(std::string(chm_rtpu_last_error()).find("not running"), std::string::npos);
    EXPECT_EQ(chm_rtpu_ping(chm_bp_self(), nullptr), -EHOSTDOWN);  // a host, not an RTPU
    EXPECT_EQ(chm_rtpu_ping(8, nullptr), -ECHRNG);
    EXPECT_EQ(chm_rtpu_ping(-1, nullptr), -ECHRNG);
    // The RTPU is still fine.
    EXPECT_EQ(chm_rtpu_ping(1, nullptr), 0);
}

TEST_F(RtpuTest, RemoteSpawnFromATaskOnAnotherRtpu) {
    create();
    const pid_t p2 = start_rtpu(2);
    ASSERT_TRUE(wait_serving(2, p2));
    const std::string probe = dir_ + "/probe.txt", result = dir_ + "/spawner.txt";
    const pid_t p1 = start_rtpu(1, {SPAWNER_SO, "2", PROBE_SO, probe, result});
    ASSERT_TRUE(wait_serving(1, p1)) << read_file(err_of(1));
    ASSERT_TRUE(wait_text(result, "self")) << read_file(err_of(1));
    const std::string r = read_file(result);
    int status = -1, n = -1, found = -1, sig = -1, self = -1;
    long long tid = -1;
    ASSERT_EQ(std::sscanf(r.c_str(), "spawn %d %lld\ntasks %d %d\nsignal %d\nself %d", &status, &tid, &n, &found, &sig,
                          &self), 6) << r;
    EXPECT_EQ(self, 0);
    EXPECT_EQ(status, 0);
    EXPECT_GE(tid, 0);
    EXPECT_EQ(n, 4);  // xmail, shutdown, stdio, probe.so
    EXPECT_EQ(found, 1);
    EXPECT_EQ(sig, 0);
    EXPECT_TRUE(wait_text(probe, "main " + std::to_string(p2))) << read_file(probe);
    EXPECT_TRUE(wait_text(probe, "signal 9")) << read_file(probe);
}

TEST_F(RtpuTest, DeadOrStalledRtpuGivesAnErrorWithinTheBound) {
    create();
    const pid_t p1 = start_rtpu(1), p2 = start_rtpu(2);
    ASSERT_TRUE(wait_serving(1, p1));
    ASSERT_TRUE(wait_serving(2, p2));

    // Stalled (SIGSTOP): alive, never replies -> -ETIMEDOUT after the timeout.
    chm_rtpu_timeout_set(300'000'000);
    ASSERT_EQ(kill(p2, SIGSTOP), 0);
    std::uint64_t t0 = now_ms();
    EXPECT_EQ(chm_rtpu_ping(2, nullptr), -ETIMEDOUT);
    std::uint64_t took = now_ms() - t0;
    EXPECT_GE(took, 290u);
    EXPECT_LT(took, 5000u);

    // Killed while a request waits: -EHOSTDOWN long before the timeout.
    chm_rtpu_timeout_set(20'000'000'000ull);
    int r = 0;
    std::uint64_t waited = 0;
    std::thread sender([&] {
        const std::uint64_t s = now_ms();
        r = chm_rtpu_ping(2, nullptr);
        waited = now_ms() - s;
    });
    nap_ms(100);
    ASSERT_EQ(kill(p2, SIGKILL), 0);
    EXPECT_EQ(reap(p2), -SIGKILL);
    sender.join();
    EXPECT_EQ(r, -EHOSTDOWN);
    EXPECT_LT(waited, 10000u);  // detection is ~10 ms; the bound is generous

    // A request to the dead slot fails at once.
    t0 = now_ms();
    ASSERT_TRUE(wait_slot(2, CHM_BP_DEAD));
    EXPECT_EQ(chm_rtpu_ping(2, nullptr), -EHOSTDOWN);
    EXPECT_LT(now_ms() - t0, 10000u);
    // The other RTPU is unaffected.
    EXPECT_EQ(chm_rtpu_ping(1, nullptr), 0);

    // Restarting the same RTPU number needs no cleanup.
    const pid_t again = start_rtpu(2);
    ASSERT_TRUE(wait_serving(2, again)) << read_file(err_of(2));
    chm_bp_status_t st;
    ASSERT_EQ(chm_bp_status(&st), 0);
    EXPECT_GE(st.slot[2].generation, 2u);
    EXPECT_EQ(chm_rtpu_ping(2, nullptr), 0);
}

TEST_F(RtpuTest, SigtermLeavesCleanlyAndRunsShutdownHooks) {
    create();
    const std::string file = dir_ + "/probe.txt";
    const pid_t p1 = start_rtpu(1, {PROBE_SO, file});
    ASSERT_TRUE(wait_serving(1, p1)) << read_file(err_of(1));
    ASSERT_TRUE(wait_text(file, "main"));
    ASSERT_EQ(kill(p1, SIGTERM), 0);
    EXPECT_EQ(reap(p1), 0) << read_file(err_of(1));
    EXPECT_TRUE(wait_text(file, "hook")) << read_file(file);
    chm_bp_status_t st;
    ASSERT_EQ(chm_bp_status(&st), 0);
    EXPECT_EQ(st.slot[1].state, CHM_BP_FREE);  // left, not dead
    EXPECT_EQ(st.slot[1].pid, 0);
    EXPECT_EQ(st.recoveries, 0u);
    EXPECT_NE(read_file(out_of(1)).find("stopped by"), std::string::npos) << read_file(out_of(1));
    EXPECT_EQ(chm_rtpu_ping(1, nullptr), -EHOSTDOWN);

    // SIGINT too, and a stop request through express mail (exit code 7).
    const pid_t p2 = start_rtpu(2, {PROBE_SO, file});
    ASSERT_TRUE(wait_serving(2, p2));
    ASSERT_EQ(kill(p2, SIGINT), 0);
    EXPECT_EQ(reap(p2), 0);
    const pid_t p3 = start_rtpu(3);
    ASSERT_TRUE(wait_serving(3, p3));
    EXPECT_EQ(chm_rtpu_stop(3, 7), 0);
    EXPECT_EQ(reap(p3), 7);
    EXPECT_TRUE(wait_slot(3, CHM_BP_FREE));
}

// A sender that dies holding records (mid-write, or before reading its
// reply) does not wedge the ring; a live sender stuck mid-write has its
// records set aside after kStaleWriteMs (STALE: it may still be writing
// into them, so nobody else gets them) and freed when it dies.
TEST_F(RtpuTest, RingSurvivesDeadAndStuckSenders) {
    create(true, 4);
    const pid_t p1 = start_rtpu(1);
    ASSERT_TRUE(wait_serving(1, p1));
    // A child claims every record of RTPU 1's ring as WRITING, then waits
    // for the word to die (or to stay, stuck).
    auto hog = [&](bool die) {
        int ready[2];
        EXPECT_EQ(pipe(ready), 0);
        std::fflush(nullptr);
        const pid_t c = fork();
        if (c == 0) {
            alarm(30);
            (void)chm_bp_attach_host(bp_.c_str(), "hog", nullptr);
            chm::bp::Attachment* a = chm::bp::current();
            chm::bp::RingHeader* ring = a->ring(1);
            for (std::uint32_t i = 0; i < ring->capacity; ++i) {
                chm::xmail::Record* rec = chm::xmail::record_at(*a, ring, i);
                rec->owner.store(a->token);
                rec->stamp_ms.store(chm::bp::mono_ms());
                rec->state.store(chm::xmail::make_state(1000 + i, chm::xmail::kWriting));
            }
            (void)!write(ready[1], "x", 1);
            if (die) _exit(0);  // _exit: no leave, a death the others recover
            pause();
            _exit(0);
        }
        children_.push_back(c);
        char x;
        EXPECT_EQ(read(ready[0], &x, 1), 1);
        close(ready[0]);
        close(ready[1]);
        return c;
    };
    const pid_t dead = hog(true);
    EXPECT_EQ(reap(dead), 0);
    EXPECT_EQ(chm_rtpu_ping(1, nullptr), 0) << chm_rtpu_last_error();

    // A sender killed holding the ring's lock (in the middle of a claim).
    std::fflush(nullptr);
    const pid_t locker = fork();
    if (locker == 0) {
        alarm(30);
        (void)chm_bp_attach_host(bp_.c_str(), "locker", nullptr);
        chm::bp::Attachment* a = chm::bp::current();
        chm::bp::lock_acquire(*a, &a->ring(1)->lock, a->token, 1000, 1'000'000'000);
        _exit(0);
    }
    children_.push_back(locker);
    EXPECT_EQ(reap(locker), 0);
    EXPECT_EQ(chm_rtpu_ping(1, nullptr), 0) << chm_rtpu_last_error();

    const pid_t stuck = hog(false);
    chm_rtpu_timeout_set(300'000'000);
    EXPECT_EQ(chm_rtpu_ping(1, nullptr), -EBUSY);  // full, for the whole (short) timeout
    chm_rtpu_timeout_set(10'000'000'000ull);
    nap_ms(chm::xmail::kStaleWriteMs + 100);
    {
        chm::bp::Attachment* a = chm::bp::current();
        chm::bp::RingHeader* ring = a->ring(1);
        (void)chm::xmail::reclaim(*a, ring);  // (or a reclaim by the server before)
        for (std::uint32_t i = 0; i < ring->capacity; ++i)
            EXPECT_EQ(chm::xmail::phase_of(chm::xmail::record_at(*a, ring, i)->state.load()), chm::xmail::kStale);
    }
    chm_rtpu_timeout_set(300'000'000);
    EXPECT_EQ(chm_rtpu_ping(1, nullptr), -EBUSY);  // set aside, not handed out
    kill(stuck, SIGKILL);
    reap(stuck);
    chm_rtpu_timeout_set(10'000'000'000ull);
    const std::uint64_t t0 = now_ms();
    EXPECT_EQ(chm_rtpu_ping(1, nullptr), 0) << chm_rtpu_last_error();  // its death frees them
    EXPECT_LT(now_ms() - t0, 10000u);
    // Many requests through the 4-record ring, from two threads at once.
    chm_rtpu_timeout_set(0);
    int fails = 0;
    std::thread other([&] {
        for (int i = 0; i < 100; ++i) fails += chm_rtpu_ping(1, nullptr) != 0;
    });
    for (int i = 0; i < 100; ++i) EXPECT_EQ(chm_rtpu_ping(1, nullptr), 0) << chm_rtpu_last_error();
    other.join();
    EXPECT_EQ(fails, 0);
    chm_rtpu_info_t info;
    ASSERT_EQ(chm_rtpu_ping(1, &info), 0);
    EXPECT_GE(info.served, 200u);
}
