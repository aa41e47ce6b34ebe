// Races in joining, recovery and express mail (issue 15, item 3), each
// provoked exactly: a child runs with CHIMERA_STOP_AT naming the instant
// (ipc/backplane/stop_point.hpp), stops itself there, the test acts from
// other processes while it is stopped, then lets it go on (SIGCONT) and
// checks the outcome. Every wait is bounded; the fixture kills and reaps
// every child, stopped or not, also when a test fails.
#include <cstdlib>
#include <fstream>
#include <string>

#include "chimera/msgq.h"
#include "chimera/rsem.h"
#include "chimera/rtpu.h"
#include "chimera/shm.h"
#include "ipc/backplane/backplane.hpp"
#include "ipc/backplane/stop_point.hpp"
#include "ipc/msgq/msgq.hpp"
#include "ipc/rsem/rsem.hpp"
#include "ipc/xmail/xmail.hpp"
#include "ipc_fixture.hpp"

namespace chm::test {
namespace {

class IpcRaces : public IpcTest {
protected:
    // A joiner of slot 1 stops at `point`; another joins the slot and holds
    // it; the first, let go, must find the slot taken (-EBUSY) and leave the
    // holder's identity intact, with `recoveries` recoveries counted and the
    // checker clean.
    void stalled_joiner_loses(const char* point, std::uint64_t recoveries);
    // A process joins `slot` and is killed there: a death to recover.
    void kill_holder_of(int slot) {
        Pipe victim_ready;
        const pid_t victim = spawn([&] {
            if (chm_bp_join(path_.c_str(), slot, "victim") != 0) return 1;
            victim_ready.put('r');
            pause();
            return 0;
        });
        ASSERT_EQ(victim_ready.get(), 'r');
        kill9(victim);
    }
};

// Wait (bounded) until no slot names process p: it left, or its death
// was recovered.
bool wait_gone(pid_t p, int timeout_ms = 5000) {
    const std::uint64_t end = now_ns() + std::uint64_t(timeout_ms) * 1000000u;
    chm_bp_status_t st;
    while (now_ns() < end) {
        bool named = chm_bp_status(&st) != 0;
        for (std::uint32_t s = 0; s < st.slots && !named; ++s) named = st.slot[s].pid == p;
        if (!named) return true;
        sleep_us(1000);
    }
    return false;
}

// A join's result as one byte for a pipe.
char join_code(int r) { return r == 0 ? 'J' : r == -EBUSY ? 'B' : r == -ETIMEDOUT ? 'T' : 'X'; }

void IpcRaces::stalled_joiner_loses(const char* point, std::uint64_t recoveries) {
    create();
    Pipe stalled_said, holder_ready, holder_go;
    const pid_t stalled = spawn([&] {
        stop_at(point);
        stalled_said.put(join_code(chm_bp_join(path_.c_str(), 1, "stalled")));
        return 0;
    });
    ASSERT_TRUE(wait_stopped(stalled));
    const pid_t holder = spawn([&] {
        if (chm_bp_join(path_.c_str(), 1, "holder") != 0) return 1;
        holder_ready.put('r');
        return holder_go.get(30000) == 'g' && chm_bp_self() == 1 ? 0 : 2;
    });
    ASSERT_EQ(holder_ready.get(), 'r');
    kill(stalled, SIGCONT);
    EXPECT_EQ(stalled_said.get(), 'B');  // the slot belongs to a live process
    EXPECT_EQ(reap(stalled), 0);         // and the stalled joiner's pid is now a dead one

    // This process's monitor recovers any slot that names a dead process.
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), "judge", nullptr), 0) << chm_bp_last_error();
    sleep_us(200000);
    chm_bp_status_t st;
    ASSERT_EQ(chm_bp_status(&st), 0);
    EXPECT_EQ(st.slot[1].state, CHM_BP_RUNNING);
    EXPECT_EQ(st.slot[1].pid, holder);
    EXPECT_STREQ(st.slot[1].name, "holder");
    EXPECT_EQ(st.recoveries, recoveries);
    EXPECT_EQ(check_now(), "");
    holder_go.put('g');
    EXPECT_EQ(reap(holder), 0);
}

// A joiner reads the slot FREE and stalls before its CAS while another
// process takes the slot. Layout 3 wrote the pid before the CAS: the loser
// then overwrote the winner's pid with its own, got -EBUSY, exited, and
// the survivors recovered the live winner's slot as dead.
TEST_F(IpcRaces, ALoserStalledBeforeItsCasLeavesTheWinnersIdentity) {
    stalled_joiner_loses("bp.take_slot.before_cas", 0);
}

// The winner of the status CAS stalls before naming itself. Another
// joiner gives it up after kConfirmMs and takes the slot; the stalled one,
// let go, must not write its identity into the slot it lost.
TEST_F(IpcRaces, AJoinerStalledBeforeNamingItselfIsGivenUpAndWritesNothing) {
    stalled_joiner_loses("bp.take_slot.before_name", 1);  // the given-up JOINING generation
}

// A joiner killed after its status CAS, before naming itself, leaves a
// JOINING slot that names nobody: the next joiner of that slot gives it up
// (after kUnnamedConfirmMs), recovers it and takes it.
TEST_F(IpcRaces, AJoinerKilledBeforeNamingItselfIsRecovered) {
    create();
    const pid_t dead = spawn([&] {
        stop_at("bp.take_slot.before_name");
        return chm_bp_join(path_.c_str(), 1, "dead") == 0 ? 0 : 1;
    });
    ASSERT_TRUE(wait_stopped(dead));
    kill9(dead);
    ASSERT_EQ(chm_bp_join(path_.c_str(), 1, "next"), 0) << chm_bp_last_error();
    chm_bp_status_t st;
    ASSERT_EQ(chm_bp_status(&st), 0);
    EXPECT_EQ(st.slot[1].pid, getpid());
    EXPECT_EQ(st.recoveries, 1u);
    EXPECT_EQ(check_now(), "");
}

// Slot 1's holder dies; the process that wins its recovery stalls right
// after winning. Layout 3 set RECOVERING and named the recoverer in two
// steps: a second process saw RECOVERING with no live recoverer, took
// over and recovered; the first, let go, recovered the same generation
// again and overwrote the slot (DEAD) under the second, which had joined.
TEST_F(IpcRaces, TwoRecoverersNeverRecoverTheSameDeathAtOnce) {
    create();
    ASSERT_NO_FATAL_FAILURE(kill_holder_of(1));

    Pipe said1, said2, go;
    auto joiner = [&](const char* name, Pipe& said, const char* point) {
        return spawn([&, name, point] {
            if (point) stop_at(point);
            const int r = chm_bp_join(path_.c_str(), 1, name);
            said.put(join_code(r));
            if (r != 0) return 0;
            return go.get(30000) == 'g' ? 0 : 2;
        });
    };
    const pid_t first = joiner("first", said1, "bp.recover.won");
    ASSERT_TRUE(wait_stopped(first));
    const pid_t second = joiner("second", said2, nullptr);
    sleep_us(300000);  // the second has found the death and acted on it
    kill(first, SIGCONT);
    const int c1 = said1.get(10000), c2 = said2.get(10000);
    EXPECT_TRUE((c1 == 'J' && c2 == 'B') || (c1 == 'B' && c2 == 'J')) << char(c1) << " " << char(c2);

    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), "judge", nullptr), 0) << chm_bp_last_error();
    chm_bp_status_t st;
    ASSERT_EQ(chm_bp_status(&st), 0);
    EXPECT_EQ(st.recoveries, 1u) << "the victim's death was recovered more than once";
    EXPECT_EQ(st.slot[1].state, CHM_BP_RUNNING);
    EXPECT_EQ(st.slot[1].pid, c1 == 'J' ? first : second);
    EXPECT_EQ(check_now(), "");
    go.put('g');
    go.put('g');
    EXPECT_EQ(reap(first), 0);
    EXPECT_EQ(reap(second), 0);
}

// The recoverer is killed right after winning: the next survivor (this
// process's monitor) takes the recovery over, exactly once.
TEST_F(IpcRaces, ARecovererKilledAfterWinningIsTakenOver) {
    create();
    ASSERT_NO_FATAL_FAILURE(kill_holder_of(1));
    const pid_t first = spawn([&] {
        stop_at("bp.recover.won");
        return chm_bp_join(path_.c_str(), 1, "first") == 0 ? 0 : 1;
    });
    ASSERT_TRUE(wait_stopped(first));
    kill9(first);
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), "judge", nullptr), 0) << chm_bp_last_error();
    ASSERT_TRUE(wait_slot_state(1, CHM_BP_DEAD, 5000));
    chm_bp_status_t st;
    ASSERT_EQ(chm_bp_status(&st), 0);
    EXPECT_EQ(st.recoveries, 1u);
    EXPECT_EQ(check_now(), "");
}

// A sender claims the only record of RTPU 1's ring and stalls before
// writing its request. After kStaleWriteMs another sender finds the ring
// full and reclaims. Layout 3 freed the record and handed it to that
// sender; the stalled one, let go, wrote its request over the new one
// (then failed its post). Now the record is set aside (STALE) until its
// stalled owner frees it.
TEST_F(IpcRaces, AStalledSenderNeverWritesIntoAnotherSendersRecord) {
    chm_bp_config_t c = small_config();
    c.ring_records = 1;
    c.ring_record_size = 256;
    create(c);
    // This process is RTPU 1 without a server: posted requests stay posted.
    ASSERT_EQ(chm_bp_join(path_.c_str(), 1, "target"), 0) << chm_bp_last_error();
    std::string mine(100, 'T'), theirs(100, 'S');
    Pipe said;
    const pid_t stalled = spawn([&] {
        if (chm_bp_attach_host(path_.c_str(), "stalled", nullptr) != 0) return 1;
        stop_at("xmail.post.before_write");
        xmail::Pending p;
        const int r = xmail::post(1, xmail::kFind, theirs.data(), std::uint32_t(theirs.size()),
                                  10'000'000'000ull, &p);
        said.put(r == -ETIMEDOUT ? 't' : r == 0 ? 'p' : 'x');
        if (r == 0) xmail::cancel(&p);
        return chm_bp_leave();
    });
    ASSERT_TRUE(wait_stopped(stalled));
    sleep_us((xmail::kStaleWriteMs + 200) * 1000);

    bp::Attachment* a = bp::current();
    xmail::Record* rec = xmail::record_at(*a, a->ring(1), 0);
    xmail::Pending p;
    int r = xmail::post(1, xmail::kFind, mine.data(), std::uint32_t(mine.size()), 300'000'000, &p);
    if (r != 0) {
        EXPECT_EQ(r, -EBUSY) << chm_rtpu_last_error();
        EXPECT_EQ(xmail::phase_of(rec->state.load()), xmail::kStale);
    }
    kill(stalled, SIGCONT);
    EXPECT_EQ(said.get(10000), 't');  // its post failed: set aside as stale
    EXPECT_EQ(reap(stalled), 0);
    if (r != 0) r = xmail::post(1, xmail::kFind, mine.data(), std::uint32_t(mine.size()), 2'000'000'000, &p);
    ASSERT_EQ(r, 0);
    EXPECT_EQ(xmail::phase_of(rec->state.load()), xmail::kPosted);
    EXPECT_EQ(rec->len, mine.size());
    EXPECT_EQ(std::string(xmail::payload_of(rec), mine.size()), mine)
        << "the stalled sender's request landed in this sender's record";
    xmail::cancel(&p);
    EXPECT_EQ(xmail::phase_of(rec->state.load()), xmail::kFree);
    EXPECT_EQ(check_now(), "");
}

// A sender killed mid-write: a dead owner's record is freed at once (no
// stale wait), and the next sender's request goes through intact.
TEST_F(IpcRaces, ASenderKilledMidWriteLosesItsRecord) {
    chm_bp_config_t c = small_config();
    c.ring_records = 1;
    c.ring_record_size = 256;
    create(c);
    ASSERT_EQ(chm_bp_join(path_.c_str(), 1, "target"), 0) << chm_bp_last_error();
    const std::string mine(100, 'T');
    const pid_t dead = spawn([&] {
        if (chm_bp_attach_host(path_.c_str(), "dead", nullptr) != 0) return 1;
        stop_at("xmail.post.before_write");
        xmail::Pending p;
        return xmail::post(1, xmail::kFind, "x", 1, 10'000'000'000ull, &p) == 0 ? 0 : 1;
    });
    ASSERT_TRUE(wait_stopped(dead));
    kill9(dead);
    ASSERT_TRUE(wait_gone(dead));  // its slot recovered by this process's monitor
    bp::Attachment* a = bp::current();
    xmail::Record* rec = xmail::record_at(*a, a->ring(1), 0);
    xmail::Pending p;
    ASSERT_EQ(xmail::post(1, xmail::kFind, mine.data(), std::uint32_t(mine.size()), 2'000'000'000, &p), 0)
        << chm_rtpu_last_error();
    EXPECT_EQ(std::string(xmail::payload_of(rec), mine.size()), mine);
    xmail::cancel(&p);
    EXPECT_EQ(check_now(), "");
}

// The open-time check of a remote semaphore (validate_sem) reads a free
// lock, the counters, every waiter record, then a free lock and the same
// counters again. A P's whole registration can fall between those two
// free-lock readings. When P stored its counters before its record, a
// registration held there (its counters new, its record not yet waiting)
// while the checker read the counters, and finished while the checker's
// scan was done, made a sound semaphore read as corrupt: "nwaiting is 1,
// 0 records wait" (seen once under ThreadSanitizer in
// IpcValidate.ALiveSemaphoreInUseIsNeverReportedCorrupt). Now records go
// first and counters last, and the checker reads counters first.
TEST_F(IpcRaces, ARegistrationBetweenTheCheckersReadingsIsNotCorruption) {
    create();
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), "judge", nullptr), 0) << chm_bp_last_error();
    chm_rsem_t* sem = nullptr;
    ASSERT_EQ(chm_rsem_create("race", CHM_SEM_COUNTING, 0, CHM_SHM_COMMON, &sem), 0) << chm_bp_last_error();
    const ipc::rsem::Rsem* s = ipc::rsem::rsem_at(sem);

    Pipe waiter_ready, waiter_go, waiter_said, checker_said;
    const pid_t waiter = spawn([&] {
        chm_rsem_t* mine = nullptr;
        if (chm_bp_attach_host(path_.c_str(), "waiter", nullptr) != 0 || chm_rsem_open("race", &mine) != 0) return 1;
        waiter_ready.put('r');
        if (waiter_go.get(30000) != 'g') return 2;
        stop_at("rsem.p.locked");
        waiter_said.put(chm_rsem_p_timed(mine, 20'000'000'000ull) == 0 ? 'P' : 'X');
        return chm_bp_leave();
    });
    ASSERT_EQ(waiter_ready.get(), 'r');
    // The checker attaches (validating every object) and opens the
    // semaphore (validating it again); it stops after its first reading of
    // a free lock, and again after its first scan of the records.
    const pid_t checker = spawn([&] {
        stop_at("rsem.validate.lock_read,rsem.validate.scanned");
        chm_rsem_t* mine = nullptr;
        int r = chm_bp_attach_host(path_.c_str(), "checker", nullptr);
        if (r == 0) r = chm_rsem_open("race", &mine);
        checker_said.put(r == 0 ? 'O' : r == -EBADMSG ? 'C' : 'X');
        if (r != 0) std::fprintf(stderr, "checker: %s\n", chm_bp_last_error());
        if (chm_bp_self() >= 0 && chm_bp_leave() != 0) return 3;  // not left as a death to recover
        return 0;
    });
    ASSERT_TRUE(wait_stopped(checker));  // it read the lock free
    waiter_go.put('g');
    ASSERT_TRUE(wait_stopped(waiter));   // P holds the lock (rsem.p.locked)
    kill(checker, SIGCONT);
    ASSERT_TRUE(wait_stopped(checker));  // it read the counters and scanned the records
    kill(waiter, SIGCONT);
    // The registration done: one waiter, the lock free again.
    const std::uint64_t end = now_ns() + 10'000'000'000ull;
    while ((s->nwaiting.load() != 1 || s->lock.token.load() != 0) && now_ns() < end) sleep_us(1000);
    ASSERT_EQ(s->nwaiting.load(), 1u);
    ASSERT_EQ(s->lock.token.load(), 0u);
    kill(checker, SIGCONT);
    EXPECT_EQ(checker_said.get(10000), 'O') << "a sound semaphore, with one waiter registered while it was "
                                                "checked, was refused as corrupt (see the checker's stderr)";
    EXPECT_EQ(reap(checker), 0);
    // Its slot freed (it left; had it died, once its death is recovered)
    // before the backplane is checked: a dead attachment not yet recovered
    // is what the check reports, not corruption of the semaphore.
    EXPECT_TRUE(wait_gone(checker));
    EXPECT_EQ(chm_rsem_v(sem), 0);
    EXPECT_EQ(waiter_said.get(10000), 'P');
    EXPECT_EQ(reap(waiter), 0);
    EXPECT_EQ(check_now(), "");
    EXPECT_EQ(chm_rsem_close(sem), 0);
}

// The same for a message queue's waiter records: the walk without its
// lock (chm_bp_validate, which chimera start and status run beside live
// RTPUs; an open walks it under its lock) read the records, then the
// waiting counts, and judged them only if the lock
// was free and no message moved from before the walk to after it. A
// receiver registering in between (no message moved) made a sound queue
// read as corrupt: "recv_waiting 1 / send_waiting 0, the records say
// 0 / 0". The stamp now holds the waiting counts and the ticket counter.
TEST_F(IpcRaces, AReceiverRegisteringDuringTheCheckersWalkIsNotCorruption) {
    create();
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), "judge", nullptr), 0) << chm_bp_last_error();
    chm_msgq_attr_t attr;
    chm_msgq_attr_init(&attr);
    attr.max_msg = 16;
    attr.max_count = 4;
    chm_msgq_t* q = nullptr;
    ASSERT_EQ(chm_msgq_create("walked", &attr, CHM_MSGQ_COMMON, &q), 0) << chm_bp_last_error();
    const auto* h = reinterpret_cast<const ipc::msgq::QueueHeader*>(q);

    Pipe receiver_ready, receiver_go, receiver_said, checker_said;
    const pid_t receiver = spawn([&] {
        chm_msgq_t* mine = nullptr;
        if (chm_bp_attach_host(path_.c_str(), "receiver", nullptr) != 0 || chm_msgq_open("walked", &mine) != 0)
            return 1;
        receiver_ready.put('r');
        if (receiver_go.get(30000) != 'g') return 2;
        char buf[16];
        const int r = chm_msgq_receive_timed(mine, buf, sizeof buf, nullptr, 20'000'000'000ull);
        if (r != 3) std::fprintf(stderr, "receiver: %d: %s\n", r, chm_bp_last_error());
        receiver_said.put(r == 3 ? 'R' : 'X');
        return chm_bp_leave();
    });
    ASSERT_EQ(receiver_ready.get(), 'r');
    const pid_t checker = spawn([&] {
        stop_at("msgq.validate.scanned");  // after the waiter records, before the waiting counts
        const int r = chm_bp_validate(path_.c_str());  // what chimera status runs beside live RTPUs
        checker_said.put(r == 0 ? 'O' : r == -EBADMSG ? 'C' : 'X');
        if (r != 0) std::fprintf(stderr, "checker: %s\n", chm_bp_last_error());
        return 0;
    });
    ASSERT_TRUE(wait_stopped(checker));
    receiver_go.put('g');
    const std::uint64_t end = now_ns() + 10'000'000'000ull;
    while ((h->recv_waiting.load() != 1 || h->lock.token.load() != 0) && now_ns() < end) sleep_us(1000);
    ASSERT_EQ(h->recv_waiting.load(), 1u) << "the receiver did not come to wait";
    ASSERT_EQ(h->lock.token.load(), 0u);
    kill(checker, SIGCONT);
    EXPECT_EQ(checker_said.get(10000), 'O') << "a sound queue, with a receiver registered while it was walked, "
                                                "was refused as corrupt (see the checker's stderr)";
    EXPECT_EQ(reap(checker), 0);
    EXPECT_EQ(chm_msgq_send(q, 0, 0, "abc", 3), 0);
    EXPECT_EQ(receiver_said.get(10000), 'R');
    EXPECT_EQ(reap(receiver), 0);
    EXPECT_EQ(check_now(), "");
    EXPECT_EQ(chm_msgq_close(q), 0);
}

// The checker (chimera-bpcheck, check_backplane) read a slot's status,
// then its other words one by one. A recovery that finished in between
// (the slot DEAD, then taken; the recoverer word cleared) read as
// "RECOVERING but its recoverer (process 0) is dead" (seen once in
// ARegistrationBetweenTheCheckersReadingsIsNotCorruption under a loaded
// CI run). A slot's words are now taken between two equal readings of its
// status.
TEST_F(IpcRaces, ARecoveryFinishingWhileTheCheckerReadsTheSlotIsNotAProblem) {
    create();
    ASSERT_NO_FATAL_FAILURE(kill_holder_of(1));
    Pipe heir_said, heir_go;
    const pid_t heir = spawn([&] {  // recovers slot 1, then takes it
        stop_at("bp.recover.recovering");
        const int r = chm_bp_join(path_.c_str(), 1, "heir");
        heir_said.put(join_code(r));
        if (r != 0) return 1;
        return heir_go.get(30000) == 'g' && chm_bp_leave() == 0 ? 0 : 2;
    });
    ASSERT_TRUE(wait_stopped(heir));  // slot 1 RECOVERING, its recoverer alive
    Pipe checker_said;
    const pid_t checker = spawn([&] {
        stop_at("bp.check.read_recovering");
        const std::string lines = check_file(path_);
        if (!lines.empty()) std::fprintf(stderr, "checker:\n%s", lines.c_str());
        checker_said.put(lines.empty() ? 'O' : 'C');
        return 0;
    });
    ASSERT_TRUE(wait_stopped(checker));  // it read slot 1's status: RECOVERING
    kill(heir, SIGCONT);
    EXPECT_EQ(heir_said.get(10000), 'J');  // recovered (DEAD, recoverer word cleared) and taken
    kill(checker, SIGCONT);
    EXPECT_EQ(checker_said.get(10000), 'O') << "a recovery that finished while the checker read the slot was "
                                                "reported as a problem (see the checker's stderr)";
    EXPECT_EQ(reap(checker), 0);
    heir_go.put('g');
    EXPECT_EQ(reap(heir), 0);
}

// A joiner between its status CAS and its naming CAS holds the previous
// generation's vacancy in the pid word: a step of the protocol (the judges
// give it up only after kUnnamedConfirmMs), which the checker reported as
// "JOINING without a pid".
TEST_F(IpcRaces, AJoinerNotNamedYetIsNoProblemToTheChecker) {
    create();
    const pid_t joiner = spawn([&] {
        stop_at("bp.take_slot.before_name");
        return chm_bp_join(path_.c_str(), 1, "joiner") == 0 && chm_bp_leave() == 0 ? 0 : 1;
    });
    ASSERT_TRUE(wait_stopped(joiner));  // slot 1 JOINING, its pid word a vacancy
    bp::View v;
    int fd = -1;
    char why[320];
    ASSERT_EQ(bp::map_file(path_.c_str(), false, &v, &fd, why, sizeof why, false), 0) << why;
    EXPECT_TRUE(bp::status_state(v.rtpu(1)->status.load()) == bp::SlotState::Joining);
    bp::unmap(&v);
    ::close(fd);
    EXPECT_EQ(check_file(path_), "") << "an unnamed joiner, a step of the protocol, was reported as a problem";
    kill(joiner, SIGCONT);
    EXPECT_EQ(reap(joiner), 0);
}

}  // namespace
}  // namespace chm::test
