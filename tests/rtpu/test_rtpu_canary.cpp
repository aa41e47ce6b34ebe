// Issue 21 item 1: identity comes from the kernel, never from the file.
// A live backplane (two RTPUs, one parked on a remote semaphore, one on a
// message queue) is copied, and in the copy every pid and thread id a
// signal could be aimed by — each slot's pid, tid, recoverer pid (start
// times set to the canary's, so the slots look alive), and every word of
// the file that held a member's pid or thread id (express-mail records,
// lock owners) — is replaced by the pid of a canary `sleep` process. Every
// doorbell is set to the state in which a ring sends a directed signal.
// Then chimera status, chimera stop, express mail, a semaphore V and a
// queue send (both grant a parked task, so they ring its RTPU) and a
// recovery run on the copy: the canary must survive all of it, and each
// refusal names the slot, the field and the value.
#include <cstring>

#include "chimera/msgq.h"
#include "chimera/rsem.h"
#include "chimera/shm.h"
#include "ipc/backplane/backplane.hpp"
#include "rtpu_fixture.hpp"

using namespace chm::test;

namespace {

bool contains(const std::string& s, const std::string& what) { return s.find(what) != std::string::npos; }

std::uint64_t start_time(pid_t pid) {
    const std::string st = read_file("/proc/" + std::to_string(pid) + "/stat");
    const std::size_t close = st.rfind(')');
    if (close == std::string::npos) return 0;
    std::istringstream in(st.substr(close + 2));
    std::string field;
    for (int f = 3; f <= 22 && in >> field; ++f)
        if (f == 22) return std::stoull(field);
    return 0;
}

class CanaryTest : public RtpuTest {
protected:
    void TearDown() override {
        if (chm_bp_self() >= 0) (void)chm_bp_leave();  // never the copy at teardown: its table names the canary
        if (canary_ > 0) {
            kill(canary_, SIGKILL);
            waitpid(canary_, nullptr, 0);
        }
        RtpuTest::TearDown();
    }

    // Alive, and not merely a zombie of ours: not reaped, not signalled.
    bool canary_alive() {
        int st = 0;
        const pid_t r = waitpid(canary_, &st, WNOHANG);
        if (r == canary_) {
            canary_status_ = WIFSIGNALED(st) ? "killed by signal " + std::to_string(WTERMSIG(st)) : "exited";
            canary_ = -1;
        }
        return r == 0;
    }

    pid_t canary_ = -1;
    std::string canary_status_;
};

TEST_F(CanaryTest, NoSignalReachesAProcessTheTableNamesFalsely) {
    create();
    chm_rsem_t* s = nullptr;
    ASSERT_EQ(chm_rsem_create("s", CHM_SEM_COUNTING, 0, CHM_SHM_COMMON, &s), 0) << chm_bp_last_error();
    chm_msgq_attr_t qa;
    chm_msgq_attr_init(&qa);
    qa.max_msg = 32;
    qa.max_count = 4;
    chm_msgq_t* q = nullptr;
    ASSERT_EQ(chm_msgq_create("q", &qa, CHM_MSGQ_COMMON, &q), 0) << chm_bp_last_error();
    const std::string n1 = dir_ + "/notes1", n2 = dir_ + "/notes2";
    const pid_t p1 = start_rtpu(1, {BLOCKER_SO, n1, "p", "s"});
    const pid_t p2 = start_rtpu(2, {BLOCKER_SO, n2, "recv", "q"});
    ASSERT_TRUE(wait_serving(1, p1)) << read_file(err_of(1));
    ASSERT_TRUE(wait_serving(2, p2)) << read_file(err_of(2));
    ASSERT_TRUE(wait_text(n1, "waiting")) << read_file(err_of(1));
    ASSERT_TRUE(wait_text(n2, "waiting")) << read_file(err_of(2));
    nap_ms(200);  // both tasks parked (their records are written before they park)

    // The canary: single-threaded, so its thread id is its pid.
    canary_ = spawn({"/bin/sleep", "120"}, dir_ + "/canary.out", dir_ + "/canary.err");
    forget(canary_);  // ours to reap (canary_alive)
    ASSERT_GT(canary_, 0);
    std::uint64_t cstart = 0;
    for (int i = 0; i < 200 && (cstart = start_time(canary_)) == 0; ++i) nap_ms(5);
    ASSERT_NE(cstart, 0u);
    while (!contains(read_file("/proc/" + std::to_string(canary_) + "/cmdline"), "sleep")) nap_ms(5);

    // The copy, planted.
    std::string img = read_file(bp_);
    ASSERT_GT(img.size(), sizeof(chm::bp::Header));
    chm_bp_status_t st;
    ASSERT_EQ(chm_bp_status(&st), 0);
    std::vector<std::uint32_t> ids;
    for (std::uint32_t k = 0; k < st.slots; ++k) {
        if (st.slot[k].pid > 0) ids.push_back(std::uint32_t(st.slot[k].pid));
        if (st.slot[k].tid > 0) ids.push_back(std::uint32_t(st.slot[k].tid));
    }
    ASSERT_GE(ids.size(), 4u);  // two RTPUs' pids and kernel threads at least
    const std::uint32_t cp = std::uint32_t(canary_);
    int planted = 0;
    for (std::size_t off = 0; off + 4 <= img.size(); off += 4) {
        std::uint32_t w;
        std::memcpy(&w, &img[off], 4);
        for (std::uint32_t id : ids)
            if (w == id) {
                std::memcpy(&img[off], &cp, 4);
                ++planted;
            }
    }
    const auto& h = *reinterpret_cast<const chm::bp::Header*>(img.data());
    for (std::uint32_t k = 0; k < h.geo.rtpu_slots; ++k) {
        auto* e = reinterpret_cast<chm::bp::RtpuEntry*>(&img[h.regions[chm::bp::kRegionTable].offset + k * 128]);
        if (chm::bp::status_state(e->status.load()) == chm::bp::SlotState::Free) continue;
        e->pid.store(cp);
        e->tid.store(cp);
        e->pid_start.store(cstart);
        e->recoverer.store(chm::bp::recoverer_word(cp, cstart));
        e->idle.store(3);  // asleep in ppoll: a ring interrupts with a directed signal
    }
    EXPECT_GT(planted, 4);
    const std::string copy = dir_ + "/copy.bp";
    {
        const int fd = open(copy.c_str(), O_WRONLY | O_CREAT | O_EXCL, 0600);
        ASSERT_GE(fd, 0);
        ASSERT_EQ(write(fd, img.data(), img.size()), ssize_t(img.size()));
        close(fd);
    }
    const std::string pid_text = "pid " + std::to_string(canary_);

    // chimera status asks each RTPU for its tasks by express mail.
    const Outcome status = run({CHIMERA_BIN, "status", "--backplane", copy});
    EXPECT_TRUE(canary_alive()) << "chimera status: " << canary_status_ << "\n" << status.out << status.err;
    EXPECT_TRUE(contains(status.err, "RTPU table slot 1: " + pid_text)) << status.out << status.err;
    EXPECT_TRUE(contains(status.err, "not signalled")) << status.err;

    // chimera stop: SIGTERM then SIGKILL to every RTPU the table names.
    const Outcome stop = run({CHIMERA_BIN, "stop", "--backplane", copy, "--timeout", "1"});
    EXPECT_TRUE(canary_alive()) << "chimera stop: " << canary_status_ << "\n" << stop.out << stop.err;
    EXPECT_EQ(stop.status, 1) << stop.out << stop.err;
    EXPECT_TRUE(contains(stop.out, "RTPU 1: not stopped")) << stop.out;
    EXPECT_TRUE(contains(stop.out, "RTPU table slot 2: " + pid_text)) << stop.out;

    // This process on the copy: express mail, a V and a send that grant
    // the parked tasks of slots 1 and 2 (their RTPUs are rung).
    (void)chm_rsem_close(s);
    (void)chm_msgq_close(q);
    ASSERT_EQ(chm_bp_leave(), 0);
    ASSERT_EQ(chm_bp_attach_host(copy.c_str(), "prober", nullptr), 0) << chm_bp_last_error();
    chm_rtpu_timeout_set(500'000'000);
    chm_rtpu_info_t info;
    EXPECT_EQ(chm_rtpu_ping(1, &info), -EPERM) << chm_bp_last_error();
    EXPECT_TRUE(contains(chm_bp_last_error(), "slot 1: " + pid_text)) << chm_bp_last_error();
    EXPECT_TRUE(canary_alive()) << "express mail: " << canary_status_;

    ASSERT_EQ(chm_rsem_open("s", &s), 0) << chm_bp_last_error();
    EXPECT_EQ(chm_rsem_v(s), 0);
    EXPECT_TRUE(contains(chm_bp_last_error(), "slot 1: tid " + std::to_string(canary_)) ||
                contains(chm_bp_last_error(), "slot 1: " + pid_text))
        << chm_bp_last_error();
    EXPECT_TRUE(canary_alive()) << "semaphore wake: " << canary_status_;
    (void)chm_rsem_close(s);

    ASSERT_EQ(chm_msgq_open("q", &q), 0) << chm_bp_last_error();
    EXPECT_EQ(chm_msgq_try_send(q, 1, 0, "hello", 6), 0) << chm_bp_last_error();
    EXPECT_TRUE(contains(chm_bp_last_error(), "slot 2: " + pid_text)) << chm_bp_last_error();
    EXPECT_TRUE(canary_alive()) << "queue wake: " << canary_status_;
    (void)chm_msgq_close(q);

    // Recovery: slot 2 shown RECOVERING by the canary, whose start time
    // no longer matches, so this host's monitor takes the recovery over
    // (the parked task's record withdrawn, its grant given back) and
    // signals nobody.
    auto* e2 = chm::bp::current()->rtpu(2);
    e2->recoverer.store(chm::bp::recoverer_word(std::uint32_t(canary_), cstart + 1));
    e2->status.store(chm::bp::make_status(chm::bp::status_gen(e2->status.load()), chm::bp::SlotState::Recovering));
    EXPECT_TRUE(wait_slot(2, CHM_BP_DEAD)) << "slot 2 was not recovered";
    EXPECT_TRUE(canary_alive()) << "recovery: " << canary_status_;
    ASSERT_EQ(chm_bp_leave(), 0);

    // The real system was not disturbed: its RTPUs still answer.
    ASSERT_EQ(chm_bp_attach_host(bp_.c_str(), "test", nullptr), 0) << chm_bp_last_error();
    EXPECT_TRUE(wait_serving(1, p1));
    EXPECT_TRUE(wait_serving(2, p2));
    EXPECT_TRUE(canary_alive()) << canary_status_;
}

}  // namespace

// Item 5, least privilege: an RTPU gives up its capabilities once set up
// (keeping only CAP_IPC_LOCK while its memory stays locked), and chimera
// start run as root says root is not needed. As root here; without root
// an RTPU starts with no capability to drop and there is nothing to see.
namespace {

std::uint64_t caps(pid_t pid, const char* key) {
    const std::string st = read_file("/proc/" + std::to_string(pid) + "/status");
    const std::size_t at = st.find(key);
    return at == std::string::npos ? ~0ull : std::stoull(st.substr(at + std::strlen(key)), nullptr, 16);
}

TEST_F(CanaryTest, AnRtpuDropsItsCapabilitiesAndRootIsNotNeeded) {
    if (geteuid() != 0) GTEST_SKIP() << "not root: an RTPU has no capability to drop";
    create();
    const pid_t p1 = start_rtpu(1);
    const pid_t p2 = start_rtpu(2, {"--lock-memory"});
    ASSERT_TRUE(wait_serving(1, p1)) << read_file(err_of(1));
    ASSERT_TRUE(wait_serving(2, p2)) << read_file(err_of(2));
    EXPECT_EQ(caps(p1, "CapEff:"), 0u);
    EXPECT_EQ(caps(p1, "CapPrm:"), 0u);
    EXPECT_EQ(caps(p2, "CapEff:"), 1ull << 14) << "CAP_IPC_LOCK only";
    EXPECT_EQ(caps(p2, "CapPrm:"), 1ull << 14);
    // They still wake each other: identity checks need no privilege.
    chm_rtpu_info_t info;
    EXPECT_EQ(chm_rtpu_ping(1, &info), 0) << chm_bp_last_error();
    EXPECT_EQ(chm_rtpu_ping(2, &info), 0) << chm_bp_last_error();

    (void)chm_bp_leave();
    const std::string other = dir_ + "/root.bp";
    unsetenv("CHIMERA_AS_ROOT");  // the test environment sets it
    Outcome r = run({CHIMERA_BIN, "start", "--backplane", other, "--rtpus", "1"});
    EXPECT_EQ(r.status, 0) << r.out << r.err;
    EXPECT_NE(r.err.find("running as root is not needed"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("CAP_SYS_NICE"), std::string::npos) << r.err;
    r = run({CHIMERA_BIN, "stop", "--backplane", other});
    EXPECT_EQ(r.status, 0) << r.out << r.err;
    r = run({CHIMERA_BIN, "rm", "--backplane", other});
}

// A member killed a moment ago, its slot not yet recovered, is gone, not a
// forgery: a ring to it used to be refused ("pid ... names no live process:
// not signalled", on stderr) and express mail to it failed with -EPERM,
// where rtpu.h promises -EHOSTDOWN once the slot is recovered (the chaos
// soak's pings met it a few times a minute; docs/backplane.md, "Chaos
// soak"). In a copy of the file, slot 1 names the killed RTPU and its
// recoverer word names a live canary, so nobody recovers the slot while
// the ping runs: it can only time out, or find the slot gone.
TEST_F(CanaryTest, AMemberThatJustDiedIsGoneNotRefused) {
    create();
    const pid_t p1 = start_rtpu(1);
    ASSERT_TRUE(wait_serving(1, p1)) << read_file(err_of(1));
    canary_ = spawn({"/bin/sleep", "120"}, dir_ + "/canary.out", dir_ + "/canary.err");
    forget(canary_);
    ASSERT_GT(canary_, 0);
    std::uint64_t cstart = 0;
    for (int i = 0; i < 200 && (cstart = start_time(canary_)) == 0; ++i) nap_ms(5);
    ASSERT_NE(cstart, 0u);
    std::string img = read_file(bp_);  // slot 1 RUNNING with p1
    kill(p1, SIGKILL);
    ASSERT_EQ(reap(p1), -SIGKILL);
    const auto& h = *reinterpret_cast<const chm::bp::Header*>(img.data());
    auto* e = reinterpret_cast<chm::bp::RtpuEntry*>(&img[h.regions[chm::bp::kRegionTable].offset + 1 * 128]);
    ASSERT_EQ(e->pid.load(), std::uint32_t(p1));
    e->recoverer.store(chm::bp::recoverer_word(std::uint32_t(canary_), cstart));
    e->idle.store(3);  // asleep in ppoll: a ring sends the directed signal
    const std::string copy = dir_ + "/dead.bp";
    {
        const int fd = open(copy.c_str(), O_WRONLY | O_CREAT | O_EXCL, 0600);
        ASSERT_GE(fd, 0);
        ASSERT_EQ(write(fd, img.data(), img.size()), ssize_t(img.size()));
        close(fd);
    }
    (void)chm_bp_leave();
    ASSERT_EQ(chm_bp_attach_host(copy.c_str(), "pinger", nullptr), 0) << chm_bp_last_error();
    chm_rtpu_timeout_set(300'000'000);
    const int r = chm_rtpu_ping(1, nullptr);
    EXPECT_TRUE(r == -ETIMEDOUT || r == -EHOSTDOWN) << r << " " << chm_bp_last_error();
    EXPECT_TRUE(canary_alive()) << canary_status_;
}

}  // namespace
