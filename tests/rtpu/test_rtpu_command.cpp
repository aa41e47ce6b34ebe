// The chimera command (start / status / stop / rm) and chimera-rtpu's
// command line, run as real processes; bad input gives one clear line and
// a non-zero exit, and leaves nothing behind.
#include <fcntl.h>
#include <sched.h>
#include <sys/mman.h>

#include "rtpu_fixture.hpp"

using namespace chm::test;

namespace {

bool contains(const std::string& s, const std::string& what) { return s.find(what) != std::string::npos; }

bool exists(const std::string& p) { return access(p.c_str(), F_OK) == 0; }

}  // namespace

TEST_F(RtpuTest, ChimeraStartStatusStopRmRoundTrip) {
    const std::string probe = dir_ + "/probe.txt";
    Outcome r = chimera({"start", "--rtpus", "2", "--program", std::string("2:") + PROBE_SO + ":" + probe});
    ASSERT_EQ(r.status, 0) << r.out << r.err;
    EXPECT_TRUE(contains(r.out, "started 2 RTPUs")) << r.out;
    EXPECT_TRUE(exists(bp_));
    EXPECT_TRUE(exists(bp_ + ".rtpu1.log"));
    EXPECT_TRUE(exists(bp_ + ".rtpu2.log"));
    EXPECT_TRUE(wait_text(probe, "main")) << read_file(bp_ + ".rtpu2.log");

    r = chimera({"status"});
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_TRUE(contains(r.out, "RTPU 1 (rtpu1")) << r.out;
    EXPECT_TRUE(contains(r.out, "RTPU 2 (rtpu2")) << r.out;
    EXPECT_TRUE(contains(r.out, "RUNNING")) << r.out;
    EXPECT_TRUE(contains(r.out, "probe.so")) << r.out;
    EXPECT_TRUE(contains(r.out, "xmail")) << r.out;
    EXPECT_TRUE(contains(r.out, "MISSES")) << r.out;

    // A second start while the system runs: refused before anything is
    // started (test_rtpu_cli.cpp checks the logs).
    r = chimera({"start", "--rtpus", "1"});
    EXPECT_EQ(r.status, 1);
    EXPECT_TRUE(contains(r.err, "is already running (the host server (pid")) << r.err;
    EXPECT_TRUE(contains(r.err, ", RTPU 1 (pid")) << r.err;
    EXPECT_TRUE(exists(bp_));  // not ours to remove

    // rm refuses while RTPUs run.
    r = chimera({"rm"});
    EXPECT_EQ(r.status, 1);
    EXPECT_TRUE(contains(r.err, "in use by the host server (pid")) << r.err;
    EXPECT_TRUE(contains(r.err, ", RTPU 1 (pid")) << r.err;

    r = chimera({"stop"});
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_TRUE(contains(r.out, "RTPU 1 (pid")) << r.out;
    EXPECT_TRUE(contains(r.out, "RTPU 2 (pid")) << r.out;
    EXPECT_FALSE(contains(r.out, "killed")) << r.out;
    // "stopped" means the process is gone (at most a zombie), not only its slot.
    for (std::size_t at = r.out.find("(pid "); at != std::string::npos; at = r.out.find("(pid ", at + 1)) {
        const int pid = std::atoi(r.out.c_str() + at + 5);
        const std::string stat = read_file("/proc/" + std::to_string(pid) + "/stat");
        const std::size_t close = stat.rfind(')');
        EXPECT_TRUE(stat.empty() || (close != std::string::npos && stat.compare(close + 2, 1, "Z") == 0))
            << "pid " << pid << " still runs after chimera stop: " << stat;
    }
    EXPECT_TRUE(wait_text(probe, "hook")) << read_file(probe);  // shutdown hooks ran
    EXPECT_TRUE(contains(read_file(bp_ + ".rtpu2.log"), "stopped by")) << read_file(bp_ + ".rtpu2.log");

    r = chimera({"status"});
    EXPECT_EQ(r.status, 0);
    EXPECT_TRUE(contains(r.out, "no RTPU running")) << r.out;

    r = chimera({"rm"});
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_FALSE(exists(bp_));
    EXPECT_FALSE(exists(bp_ + ".rtpu1.log"));
    EXPECT_FALSE(exists(bp_ + ".rtpu2.log"));
}

// Issue 15 item 4: status refuses a table that fails validation, and
// start validates an existing file before it forks anything.
TEST_F(RtpuTest, ChimeraStatusAndStartRefuseACorruptBackplane) {
    chm_bp_config_t cfg;
    chm_bp_config_init(&cfg);
    cfg.rtpu_slots = 4;
    ASSERT_EQ(chm_bp_create(bp_.c_str(), &cfg), 0) << chm_bp_last_error();
    {
        const int fd = open(bp_.c_str(), O_RDWR);
        ASSERT_GE(fd, 0);
        std::uint32_t hdr[56];  // the header's first 224 bytes (layout.hpp)
        ASSERT_EQ(pread(fd, hdr, sizeof hdr, 0), ssize_t(sizeof hdr));
        const std::uint32_t rings = hdr[16], stride = hdr[24];  // regions[rings].offset, ring_stride
        const std::uint32_t zero = 0;  // ring 1's capacity
        ASSERT_EQ(pwrite(fd, &zero, sizeof zero, off_t(rings) + stride), ssize_t(sizeof zero));
        close(fd);
    }
    Outcome r = chimera({"status"});
    EXPECT_EQ(r.status, 1);
    EXPECT_TRUE(contains(r.err, "refusing")) << r.err;
    EXPECT_TRUE(contains(r.err, "ring[1].capacity is 0")) << r.err;
    r = chimera({"start", "--rtpus", "1"});
    EXPECT_EQ(r.status, 1);
    EXPECT_TRUE(contains(r.err, "ring[1].capacity is 0")) << r.err;
    EXPECT_FALSE(exists(bp_ + ".rtpu1.log"));  // nothing was forked
    EXPECT_TRUE(exists(bp_));                  // and the file is not ours to remove
}

TEST_F(RtpuTest, ChimeraStopKillsAnRtpuThatWillNotStop) {
    Outcome r = chimera({"start", "--rtpus", "1"});
    ASSERT_EQ(r.status, 0) << r.err;
    ASSERT_EQ(chm_bp_attach_host(bp_.c_str(), "test", nullptr), 0);
    chm_bp_status_t st;
    ASSERT_EQ(chm_bp_status(&st), 0);
    const pid_t pid = st.slot[1].pid;
    ASSERT_GT(pid, 0);
    kill(pid, SIGSTOP);  // SIGTERM stays pending: it must be killed
    r = chimera({"stop", "--timeout", "0.3"});
    EXPECT_EQ(r.status, 0) << r.err;
    EXPECT_TRUE(contains(r.out, "killed")) << r.out;
    EXPECT_TRUE(wait_slot(1, CHM_BP_DEAD)) << "state " << st.slot[1].state;
}

TEST_F(RtpuTest, ChimeraBadInputGivesOneClearLine) {
    struct Case {
        std::vector<std::string> args;
        bool with_backplane;
        int status;
        std::string says;
    };
    const std::string text = dir_ + "/text.bp";
    { std::ofstream(text) << "not a backplane\n"; }
    chmod(text.c_str(), 0600);  // ours alone: refused for what it holds, not for who may touch it
    const std::string notso = dir_ + "/text.so";
    { std::ofstream(notso) << "not an ELF file\n"; }
    const Case cases[] = {
        {{"frob"}, false, 2, "unknown command \"frob\""},
        {{"start", "--rtpus", "0"}, true, 2, "--rtpus wants 1..30"},
        {{"start", "--rtpus", "two"}, true, 2, "--rtpus wants 1..30"},
        {{"start", "--rtpus"}, true, 2, "option --rtpus needs a value"},
        {{"start", "--program", "nocolon"}, true, 2, "RTPU:PATH"},
        {{"start", "--program", "1:"}, true, 2, "no program path"},
        {{"start", "--program", "1:/no/such.so"}, true, 1, "/no/such.so: No such file"},
        {{"start", "--rtpus", "1", "--program", std::string("2:") + PROBE_SO}, true, 2, "only 1 RTPUs"},
        {{"start", "--policy", "fifo"}, true, 2, "unknown policy \"fifo\""},
        {{"start", "--rt-priority", "100"}, true, 2, "--rt-priority wants a SCHED_FIFO priority 1..99, not \"100\""},
        {{"start", "--idle-poll", "x"}, true, 2, "--idle-poll wants microseconds 0..100000, not \"x\""},
        {{"start", "--timer-lead", "-5"}, true, 2, "--timer-lead wants microseconds 0..1000 or auto, not \"-5\""},
        {{"stop", "--pin"}, true, 2, "chimera stop: unknown option --pin"},
        {{"start", "--timeout", "-1"}, true, 2, "--timeout wants seconds"},
        {{"start", "--rtpus", "1", "--program", "1:" + notso}, true, 1, "cannot load"},
        {{"status", "--bogus"}, true, 2, "unknown option --bogus"},
        {{"start", "--group", "no-such-group-chimera"}, true, 2, "--group: no group \"no-such-group-chimera\""},
        {{"start", "--programs", dir_ + "/none"}, true, 1, "--programs " + dir_ + "/none: No such file"},
        {{"start", "--programs", text}, true, 2, "not a directory"},
        {{"status"}, true, 1, "no backplane at"},
        {{"stop"}, true, 1, "no backplane at"},
        {{"rm"}, true, 1, "no backplane at"},
        {{"rm", "--backplane", text}, false, 1, "not a usable backplane file"},
    };
    for (const Case& c : cases) {
        std::vector<std::string> args = c.args;
        const Outcome r = chimera(args, c.with_backplane);
        std::string all;
        for (auto& a : c.args) all += a + " ";
        EXPECT_EQ(r.status, c.status) << all << "\n" << r.out << r.err;
        EXPECT_TRUE(contains(r.err, c.says)) << all << ": " << r.err;
        EXPECT_EQ(count_lines(r.err), 1) << all << ": " << r.err;
        EXPECT_FALSE(exists(bp_)) << all;  // a failed start leaves no backplane behind
        EXPECT_FALSE(exists(bp_ + ".rtpu1.log")) << all;
    }
    EXPECT_TRUE(exists(text));  // rm refused it
    const Outcome help = chimera({"--help"}, false);
    EXPECT_EQ(help.status, 0);
    EXPECT_TRUE(contains(help.out, "usage: chimera start"));
}

TEST_F(RtpuTest, ChimeraRtpuBadInputGivesOneClearLine) {
    create(false);
    const std::string notso = dir_ + "/text.so";
    { std::ofstream(notso) << "not an ELF file\n"; }
    const std::string missing = dir_ + "/missing.bp";
    struct Case {
        std::vector<std::string> args;
        int status;
        const char* says;
    };
    const Case cases[] = {
        {{}, 2, "--rtpu N is required"},
        {{"--rtpu", "x"}, 2, "--rtpu wants an RTPU number"},
        {{"--rtpu", "0", "--backplane", bp_}, 2, "RTPU 0 is the host server"},
        {{"--rtpu"}, 2, "option --rtpu needs a value"},
        {{"--rtpu", "1", "--policy", "fifo"}, 2, "unknown policy \"fifo\""},
        {{"--rtpu", "1", "--frob"}, 2, "unknown option --frob"},
        {{"--rtpu", "1", "--rt-priority", "0"}, 2, "--rt-priority wants a SCHED_FIFO priority 1..99, not \"0\""},
        {{"--rtpu", "1", "--cpu", "-1"}, 2, "--cpu wants a CPU number, not \"-1\""},
        {{"--rtpu", "1", "--cpu", "1000"}, 2, "--cpu 1000: this process may not run on that CPU"},
        {{"--rtpu", "1", "--idle-poll", "100001"}, 2, "--idle-poll wants microseconds 0..100000"},
        {{"--rtpu", "1", "--timer-lead", "1001"}, 2, "--timer-lead wants microseconds 0..1000 or auto, not \"1001\""},
        {{"--rtpu", "1", "--timer-lead", "soon"}, 2, "--timer-lead wants microseconds 0..1000 or auto"},
        {{"--rtpu", "1", "--backplane", missing}, 1, "No such file"},
        {{"--rtpu", "1", "--backplane", notso}, 1, "cannot join as RTPU 1"},
        {{"--rtpu", "9", "--backplane", bp_}, 1, "out of range"},
        {{"--rtpu", "1", "--backplane", bp_, dir_ + "/none.so"}, 1, "none.so: No such file"},
        {{"--rtpu", "1", "--backplane", bp_, notso}, 1, "cannot load"},
        {{"--rtpu", "1", "--backplane", bp_, NOMAIN_SO}, 1, "cannot load"},
    };
    for (const Case& c : cases) {
        std::vector<std::string> args = {CHIMERA_RTPU_BIN};
        args.insert(args.end(), c.args.begin(), c.args.end());
        const Outcome r = run(args);
        std::string all;
        for (auto& a : c.args) all += a + " ";
        EXPECT_EQ(r.status, c.status) << all << "\n" << r.out << r.err;
        EXPECT_TRUE(contains(r.err, c.says)) << all << ": " << r.err;
        EXPECT_EQ(count_lines(r.err), 1) << all << ": " << r.err;
    }
    // A taken number: the second process says who has it.
    ASSERT_EQ(chm_bp_attach_host(bp_.c_str(), "test", nullptr), 0);
    const pid_t p1 = start_rtpu(1);
    ASSERT_TRUE(wait_serving(1, p1));
    const Outcome r = run({CHIMERA_RTPU_BIN, "--backplane", bp_, "--rtpu", "1"});
    EXPECT_EQ(r.status, 1);
    EXPECT_TRUE(contains(r.err, "belongs to live process " + std::to_string(p1))) << r.err;
    EXPECT_EQ(count_lines(r.err), 1) << r.err;
    // Failed loads left the slot free for the next one; a failed start
    // did not disturb the running RTPU.
    EXPECT_EQ(chm_rtpu_ping(1, nullptr), 0);
    const Outcome help = run({CHIMERA_RTPU_BIN, "--help"});
    EXPECT_EQ(help.status, 0);
    EXPECT_TRUE(contains(help.out, "usage: chimera-rtpu"));
}

// A backplane made elsewhere with rings too small for express mail: the
// RTPUs still run (and say so); status says why it cannot list tasks.
TEST_F(RtpuTest, ChimeraOnABackplaneWithoutExpressMail) {
    create(false, 8, 64);
    Outcome r = chimera({"start", "--rtpus", "1"});
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_TRUE(contains(r.err, "no express mail")) << r.err;
    // The RTPU writes its warning after it joined, so `start`, which
    // waits for the join and a ping, may return before the line is in.
    EXPECT_TRUE(wait_text(bp_ + ".rtpu1.log", "no express mail", 10000)) << read_file(bp_ + ".rtpu1.log");
    r = chimera({"status"});
    EXPECT_EQ(r.status, 0);
    EXPECT_TRUE(contains(r.out, "RTPU 1 (rtpu1")) << r.out;
    EXPECT_TRUE(contains(r.out, "below 128")) << r.out;
    r = chimera({"stop"});
    EXPECT_EQ(r.status, 0);
    EXPECT_TRUE(contains(r.out, "RTPU 1 (pid")) << r.out;
    EXPECT_FALSE(contains(r.out, "killed")) << r.out;
    EXPECT_EQ(chimera({"rm"}).status, 0);
}

// Whether this process may ask for SCHED_FIFO and lock its memory (root, or
// CAP_SYS_NICE / CAP_IPC_LOCK, or rlimits that allow it): tried in a child.
static bool host_grants_realtime() {
    const pid_t p = fork();
    if (p == 0) {
        sched_param sp{};
        sp.sched_priority = 1;
        _exit(sched_setscheduler(0, SCHED_FIFO, &sp) == 0 && mlockall(MCL_CURRENT) == 0 ? 0 : 1);
    }
    int st = 0;
    return p > 0 && waitpid(p, &st, 0) == p && WIFEXITED(st) && WEXITSTATUS(st) == 0;
}

// Field `n` (1-based) of /proc/PID/stat, counted after the command name.
static long proc_stat_field(pid_t pid, int n) {
    const std::string s = read_file("/proc/" + std::to_string(pid) + "/stat");
    const std::size_t close = s.rfind(')');
    if (close == std::string::npos) return -1;
    std::istringstream in(s.substr(close + 2));
    std::string f;
    for (int i = 3; i <= n && in >> f; ++i) {
    }
    return std::strtol(f.c_str(), nullptr, 10);
}

// chimera start --rt-priority --pin --lock-memory --idle-poll: every RTPU
// runs SCHED_FIFO at that priority, alone on its CPU (RTPU n on the n-th
// allowed), with its memory locked, and its log says so.
TEST_F(RtpuTest, ChimeraStartAsksTheHostForRealTime) {
    if (!host_grants_realtime()) GTEST_SKIP() << "this process may not use SCHED_FIFO or mlockall here";
    Outcome r = chimera({"start", "--rtpus", "2", "--rt-priority", "7", "--pin", "--lock-memory", "--idle-poll", "50"});
    ASSERT_EQ(r.status, 0) << r.out << r.err;
    ASSERT_EQ(chm_bp_attach_host(bp_.c_str(), "test", nullptr), 0);
    chm_bp_status_t st;
    ASSERT_EQ(chm_bp_status(&st), 0);
    cpu_set_t allowed;
    ASSERT_EQ(sched_getaffinity(0, sizeof allowed, &allowed), 0);
    std::vector<int> cpus;
    for (int c = 0; c < CPU_SETSIZE; ++c)
        if (CPU_ISSET(c, &allowed)) cpus.push_back(c);
    for (int n = 1; n <= 2; ++n) {
        const pid_t pid = st.slot[n].pid;
        ASSERT_GT(pid, 0);
        EXPECT_EQ(proc_stat_field(pid, 41), SCHED_FIFO) << "RTPU " << n;
        EXPECT_EQ(proc_stat_field(pid, 40), 7) << "RTPU " << n;
        cpu_set_t on;
        ASSERT_EQ(sched_getaffinity(pid, sizeof on, &on), 0);
        EXPECT_EQ(CPU_COUNT(&on), 1) << "RTPU " << n;
        EXPECT_TRUE(CPU_ISSET(cpus[std::size_t(n - 1) % cpus.size()], &on)) << "RTPU " << n;
        const std::string status = read_file("/proc/" + std::to_string(pid) + "/status");
        const std::size_t lck = status.find("VmLck:");
        ASSERT_NE(lck, std::string::npos);
        EXPECT_GT(std::strtol(status.c_str() + lck + 6, nullptr, 10), 0) << "RTPU " << n << " locked no memory";
        const std::string log = read_file(bp_ + ".rtpu" + std::to_string(n) + ".log");
        EXPECT_TRUE(contains(log, "SCHED_FIFO 7, CPU " + std::to_string(cpus[std::size_t(n - 1) % cpus.size()]) +
                                      ", memory locked, idle poll 50 us"))
            << log;
    }
    (void)chm_bp_leave();
    r = chimera({"stop"});
    EXPECT_EQ(r.status, 0) << r.err;
    EXPECT_FALSE(contains(r.out, "killed")) << r.out;
}
