// The operator's commands (issue 19 item 7): chimera load, kill, stop
// --rtpu, objects, status --watch, and start's refusal of a running
// system, each run as a real process against real RTPUs.
#include <fcntl.h>

#include "chimera/msgq.h"
#include "chimera/rsem.h"
#include "chimera/shm.h"
#include "chimera/svar.h"
#include "rtpu_fixture.hpp"

using namespace chm::test;

namespace {

bool contains(const std::string& s, const std::string& what) { return s.find(what) != std::string::npos; }

// The line of `text` that contains `what` ("" when none).
std::string line_with(const std::string& text, const std::string& what) {
    const std::size_t at = text.find(what);
    if (at == std::string::npos) return "";
    const std::size_t b = text.rfind('\n', at);
    const std::size_t e = text.find('\n', at);
    return text.substr(b == std::string::npos ? 0 : b + 1, e == std::string::npos ? std::string::npos : e - b - 1);
}

// A duration as status prints it ("850ns", "12.3us", "4.56ms", "1.2s") in us.
double to_us(const std::string& s) {
    const double v = std::atof(s.c_str());
    if (s.find("ns") != std::string::npos) return v / 1e3;
    if (s.find("us") != std::string::npos) return v;
    if (s.find("ms") != std::string::npos) return v * 1e3;
    return v * 1e6;
}

// "... task N" at the end of chimera load's line.
int task_of(const std::string& out) {
    const std::size_t at = out.rfind("task ");
    return at == std::string::npos ? -1 : std::atoi(out.c_str() + at + 5);
}

class CliTest : public RtpuTest {
protected:
    void start2() {
        const Outcome r = chimera({"start", "--rtpus", "2"});
        ASSERT_EQ(r.status, 0) << r.out << r.err;
        ASSERT_EQ(chm_bp_attach_host(bp_.c_str(), "test", nullptr), 0) << chm_bp_last_error();
    }
    // The task list of RTPU n has a task of that id (and name, if given).
    bool has_task(int n, int id, const char* name = nullptr) {
        chm_rtpu_task_t t[64];
        const int k = chm_rtpu_tasks(n, t, 64, nullptr);
        for (int i = 0; i < k; ++i)
            if (t[i].id == id && (!name || std::string(t[i].name) == name)) return true;
        return false;
    }
};

}  // namespace

TEST_F(CliTest, LoadOnTwoRtpusAndKillByIdAndByName) {
    start2();
    const std::string f1 = dir_ + "/p1.txt", f2 = dir_ + "/p2.txt";
    Outcome r = chimera({"load", "1", PROBE_SO, f1});
    ASSERT_EQ(r.status, 0) << r.out << r.err;
    EXPECT_TRUE(contains(r.out, std::string("loaded ") + PROBE_SO + " on RTPU 1: task ")) << r.out;
    const int t1 = task_of(r.out);
    r = chimera({"load", "rtpu2", PROBE_SO, f2});  // an RTPU by its name
    ASSERT_EQ(r.status, 0) << r.out << r.err;
    EXPECT_TRUE(contains(r.out, "on RTPU 2: task ")) << r.out;
    const int t2 = task_of(r.out);
    // Both mains run, with their arguments, on their own RTPUs.
    EXPECT_TRUE(wait_text(f1, "main"));
    EXPECT_TRUE(wait_text(f2, "main"));
    EXPECT_TRUE(has_task(1, t1, "probe.so"));
    EXPECT_TRUE(has_task(2, t2, "probe.so"));

    r = chimera({"kill", "1", std::to_string(t1)});
    EXPECT_EQ(r.status, 0) << r.err;
    EXPECT_TRUE(contains(r.out, "RTPU 1: task " + std::to_string(t1) + " (probe.so) destroyed")) << r.out;
    EXPECT_FALSE(has_task(1, t1));
    r = chimera({"kill", "2", "probe.so"});
    EXPECT_EQ(r.status, 0) << r.err;
    EXPECT_TRUE(contains(r.out, "RTPU 2: task " + std::to_string(t2) + " (probe.so) destroyed")) << r.out;
    EXPECT_FALSE(has_task(2, t2));
    EXPECT_EQ(chm_rtpu_ping(1, nullptr), 0);  // the RTPUs run on
    EXPECT_EQ(chm_rtpu_ping(2, nullptr), 0);
}

TEST_F(CliTest, UnknownRtpuTaskOrProgramGiveOneClearLine) {
    start2();
    const std::string text = dir_ + "/text.so";
    { std::ofstream(text) << "not an ELF file\n"; }
    chmod(text.c_str(), 0600);
    chm_tid_t xmail = CHM_TID_NONE;
    ASSERT_EQ(chm_rtpu_find(1, "xmail", &xmail), 0);
    struct Case {
        std::vector<std::string> args;
        int status;
        std::string says;
    };
    const Case cases[] = {
        {{"load", "5", PROBE_SO}, 1, "RTPU 5 is not running (its slot is free"},
        {{"load", "40", PROBE_SO}, 1, "no RTPU 40: this backplane has RTPUs 1..31"},
        {{"load", "nosuch", PROBE_SO}, 1, "no RTPU named \"nosuch\""},
        {{"load", "0", PROBE_SO}, 1, "no RTPU 0"},
        {{"load", "1", dir_ + "/none.so"}, 1, "load: program " + dir_ + "/none.so: No such file or directory"},
        {{"load", "1", dir_}, 1, "load: program " + dir_ + " is not a file"},
        {{"load", "1", NOMAIN_SO}, 1,
         std::string("load: RTPU 1 cannot load ") + NOMAIN_SO + ": no main: a control program defines int main"},
        {{"load", "1", text}, 1, "load: RTPU 1 cannot load " + text + ": "},
        {{"load", "1", LINKED_SO}, 1,
         std::string("load: RTPU 1 cannot load ") + LINKED_SO + ": linked against libchimera.so.0: a control program"},
        {{"load", "1"}, 2, "load wants RTPU PROGRAM [ARG...]"},
        {{"kill", "1"}, 2, "kill wants RTPU TASK"},
        {{"kill", "9", "1"}, 1, "RTPU 9 is not running"},
        {{"kill", "1", "nosuch"}, 1, "kill: RTPU 1 has no task named \"nosuch\""},
        {{"kill", "1", "12345"}, 1, "kill: RTPU 1 has no task 12345"},
        {{"kill", "1", std::to_string(xmail)}, 1, "express-mail server: not destroyed"},
        {{"stop", "--rtpu", "6"}, 1, "RTPU 6 is not running"},
        {{"stop", "--rtpu", "x"}, 2, "--rtpu wants an RTPU number"},
        {{"status", "--count", "2"}, 2, "go with status --watch"},
        {{"status", "--watch", "--interval", "0"}, 2, "--interval wants seconds 0.1..3600"},
    };
    for (const Case& c : cases) {
        const Outcome r = chimera(c.args);
        std::string all;
        for (auto& a : c.args) all += a + " ";
        EXPECT_EQ(r.status, c.status) << all << "\n" << r.out << r.err;
        EXPECT_TRUE(contains(r.err, c.says)) << all << ": " << r.err;
        EXPECT_EQ(count_lines(r.err), 1) << all << ": " << r.err;
        // The file is named once, not again after a second strerror.
        if (c.says.find("cannot load") != std::string::npos) {
            const std::string file = c.args[2];
            EXPECT_EQ(r.err.find(file, r.err.find(file) + 1), std::string::npos) << r.err;
        }
    }
    EXPECT_EQ(chm_rtpu_ping(1, nullptr), 0);
}

TEST_F(CliTest, StopOneRtpuLeavesTheOtherRunning) {
    start2();
    const std::string f1 = dir_ + "/p1.txt";
    ASSERT_EQ(chimera({"load", "1", PROBE_SO, f1}).status, 0);
    ASSERT_TRUE(wait_text(f1, "main"));
    chm_bp_status_t st;
    ASSERT_EQ(chm_bp_status(&st), 0);
    const pid_t p1 = st.slot[1].pid, p2 = st.slot[2].pid;
    const Outcome r = chimera({"stop", "--rtpu", "1"});
    EXPECT_EQ(r.status, 0) << r.err;
    EXPECT_TRUE(contains(r.out, "RTPU 1 (pid " + std::to_string(p1) + "): stopped")) << r.out;
    EXPECT_FALSE(contains(r.out, "RTPU 2")) << r.out;
    EXPECT_TRUE(wait_text(f1, "hook")) << "RTPU 1's shutdown hooks did not run";  // graceful: express mail
    EXPECT_TRUE(wait_slot(1, CHM_BP_FREE));
    ASSERT_EQ(chm_bp_status(&st), 0);
    EXPECT_EQ(st.slot[2].state, CHM_BP_RUNNING);
    EXPECT_EQ(st.slot[2].pid, p2);
    EXPECT_EQ(chm_rtpu_ping(2, nullptr), 0);
    EXPECT_EQ(kill(p2, 0), 0);
}

TEST_F(CliTest, ObjectsListsEveryKindWithItsFigures) {
    start2();
    // A queue with 3 messages in it, an empty queue a task waits on, a
    // semaphore of value 2, one of value 0 a task waits on, a segment and
    // a state variable.
    chm_msgq_attr_t qa;
    chm_msgq_attr_init(&qa);
    chm_msgq_t *full = nullptr, *empty = nullptr;
    ASSERT_EQ(chm_msgq_create("cli.full", &qa, CHM_MSGQ_COMMON, &full), 0) << chm_bp_last_error();
    for (int i = 0; i < 3; ++i) ASSERT_EQ(chm_msgq_send(full, 1, 0, "hello", 5), 0);
    ASSERT_EQ(chm_msgq_create("cli.empty", &qa, 2, &empty), 0) << chm_bp_last_error();
    chm_rsem_t *two = nullptr, *zero = nullptr;
    ASSERT_EQ(chm_rsem_create("cli.two", CHM_SEM_COUNTING, 2, CHM_MSGQ_COMMON, &two), 0) << chm_bp_last_error();
    ASSERT_EQ(chm_rsem_create("cli.zero", CHM_SEM_COUNTING, 0, CHM_MSGQ_COMMON, &zero), 0) << chm_bp_last_error();
    void* seg = nullptr;
    ASSERT_EQ(chm_shm_create("cli.seg", 4096, -1, &seg), 0) << chm_bp_last_error();
    const chm_svar_decl_t d{"cli_speed", CHM_SVAR_DOUBLE, 3, 1, "m/s"};
    ASSERT_EQ(chm_svar_declare(&d), 0) << chm_bp_last_error();
    const std::string fr = dir_ + "/recv.txt", fp = dir_ + "/p.txt";
    ASSERT_EQ(chimera({"load", "1", BLOCKER_SO, fr, "recv", "cli.empty"}).status, 0);
    ASSERT_EQ(chimera({"load", "2", BLOCKER_SO, fp, "p", "cli.zero"}).status, 0);
    ASSERT_TRUE(wait_text(fr, "waiting"));
    ASSERT_TRUE(wait_text(fp, "waiting"));
    // The waits are entered just after the note: poll (bounded) for them.
    Outcome r;
    const std::uint64_t end = now_ms() + 5000;
    do {
        r = chimera({"objects"});
    } while ((!contains(line_with(r.out, "cli.empty"), "1 receiver") ||
              !contains(line_with(r.out, "cli.zero"), "1 waiter")) &&
             now_ms() < end && (nap_ms(50), true));
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_TRUE(contains(line_with(r.out, "cli.full"), "queue")) << r.out;
    EXPECT_TRUE(contains(line_with(r.out, "cli.full"), "fill 3/64 messages, 15 bytes")) << r.out;
    EXPECT_TRUE(contains(line_with(r.out, "cli.full"), "0 receivers, 0 senders")) << r.out;
    EXPECT_TRUE(contains(line_with(r.out, "cli.empty"), "rtpu2")) << r.out;
    EXPECT_TRUE(contains(line_with(r.out, "cli.empty"), "fill 0/64 messages")) << r.out;
    EXPECT_TRUE(contains(line_with(r.out, "cli.empty"), "waiting: 1 receiver, 0 senders")) << r.out;
    EXPECT_TRUE(contains(line_with(r.out, "cli.two"), "semaphore")) << r.out;
    EXPECT_TRUE(contains(line_with(r.out, "cli.two"), "value 2, 0 waiters")) << r.out;
    EXPECT_TRUE(contains(line_with(r.out, "cli.zero"), "value 0, 1 waiter")) << r.out;
    EXPECT_TRUE(contains(line_with(r.out, "cli.seg"), "shm")) << r.out;
    EXPECT_TRUE(contains(line_with(r.out, "cli.seg"), "shared memory segment")) << r.out;
    EXPECT_TRUE(contains(line_with(r.out, "cli_speed"), "double")) << r.out;
    EXPECT_TRUE(contains(line_with(r.out, "cli_speed"), "3x1")) << r.out;
    EXPECT_TRUE(contains(line_with(r.out, "cli_speed"), "m/s")) << r.out;
    (void)chm_msgq_close(full);
    (void)chm_msgq_close(empty);
    (void)chm_rsem_close(two);
    (void)chm_rsem_close(zero);
    (void)chm_shm_detach(seg);
}

TEST_F(CliTest, StatusWatchShowsTheTimingColumnsAndUtilisation) {
    start2();
    // 2 ms period, 400 us declared, ~200 us spent per cycle: utilisation
    // near 10 % (20 % declared), in the critical set.
    ASSERT_EQ(chimera({"load", "1", PERIODIC_SO, "2000", "400"}).status, 0);
    nap_ms(500);
    const Outcome r = chimera({"status", "--watch", "--count", "2", "--interval", "0.3"});
    ASSERT_EQ(r.status, 0) << r.err;
    // Two frames, each drawn from the top of the screen, lines cleared.
    int frames = 0;
    for (std::size_t at = r.out.find("\x1b[H"); at != std::string::npos; at = r.out.find("\x1b[H", at + 1)) ++frames;
    EXPECT_EQ(frames, 3) << r.out;  // one to clear the screen, one per frame
    EXPECT_TRUE(contains(r.out, "\x1b[K\n")) << r.out;
    const std::string second = r.out.substr(r.out.rfind("chimera status --watch"));
    for (const char* col : {"CPU%", "CYCLES", "MISSES", "LATE MAX", "CPU/CYC", "STACK HW"})
        EXPECT_TRUE(contains(second, col)) << col << "\n" << second;
    EXPECT_TRUE(contains(second, "over the last refresh")) << second;
    const std::string row = line_with(second, "cycler");
    ASSERT_FALSE(row.empty()) << second;
    std::istringstream in(row);
    std::string tid, name, state, prio, crit, period, cpu, cycles, misses, late, cyc, stack;
    in >> tid >> name >> state >> prio >> crit >> period >> cpu >> cycles >> misses >> late >> cyc >> stack;
    EXPECT_EQ(crit, "*") << row;
    EXPECT_EQ(period, "2ms") << row;
    EXPECT_GT(std::atof(cpu.c_str()), 2.0) << row;  // ~10 % of a CPU, measured over the refresh
    EXPECT_LT(std::atof(cpu.c_str()), 60.0) << row;
    EXPECT_GT(std::atol(cycles.c_str()), 100) << row;
    // Worst CPU of a cycle: some 200 us, more when Linux took the CPU away
    // mid-cycle (the kernel counts the time its task held the RTPU).
    EXPECT_GE(to_us(cyc), 150.0) << row;
    EXPECT_GT(std::atof(stack.c_str()), 0.0) << row;  // KiB of stack used
    const std::string util = line_with(second.substr(second.find("RTPU 1 (")), "utilisation");
    EXPECT_TRUE(contains(util, "periodic tasks (1)")) << util;
    EXPECT_TRUE(contains(util, "MUF critical set (1)")) << util;
    EXPECT_TRUE(contains(util, "| 20.0%")) << util;  // declared: 400 us / 2 ms
    const double mean = std::atof(util.c_str() + util.find("periodic tasks (1) ") + 19);
    EXPECT_GT(mean, 5.0) << util;
    EXPECT_LT(mean, 60.0) << util;
}

TEST_F(CliTest, StartRefusesARunningSystemAndKeepsItsLog) {
    Outcome r = chimera({"start", "--rtpus", "1"});
    ASSERT_EQ(r.status, 0) << r.err;
    ASSERT_EQ(chm_bp_attach_host(bp_.c_str(), "test", nullptr), 0);
    const std::string log = bp_ + ".rtpu1.log";
    ASSERT_TRUE(wait_text(log, "joined"));
    const std::string before = read_file(log);
    ASSERT_FALSE(before.empty());
    chm_bp_status_t st;
    ASSERT_EQ(chm_bp_status(&st), 0);
    const pid_t pid = st.slot[1].pid;
    r = chimera({"start", "--rtpus", "2"});
    EXPECT_EQ(r.status, 1);
    EXPECT_TRUE(contains(r.err, "is already running (the host server (pid ")) << r.err;
    EXPECT_TRUE(contains(r.err, ", RTPU 1 (pid " + std::to_string(pid) + "))")) << r.err;
    EXPECT_EQ(count_lines(r.err), 1) << r.err;
    EXPECT_EQ(read_file(log), before);  // not truncated, not even appended to
    EXPECT_FALSE(access((bp_ + ".rtpu2.log").c_str(), F_OK) == 0);  // nothing was started
    ASSERT_EQ(chm_bp_status(&st), 0);
    EXPECT_EQ(st.slot[1].pid, pid);
    EXPECT_EQ(st.slot[2].state, CHM_BP_FREE);
    // Once it is stopped, a new start appends to the old log.
    (void)chm_bp_leave();
    ASSERT_EQ(chimera({"stop"}).status, 0);
    r = chimera({"start", "--rtpus", "1"});
    ASSERT_EQ(r.status, 0) << r.err;
    const std::string after = read_file(log);
    EXPECT_EQ(after.compare(0, before.size(), before), 0) << "the old log was not kept:\n" << after;
    EXPECT_TRUE(contains(after.substr(before.size()), "chimera start: ")) << after;
}
