// The global state-variable table in one process and with dead peers:
// declarations, sets and their copy-in/copy-out, the one-writer rule and
// when a claim ends, a writer that dies in the middle of a write, and a
// corrupt table in the file.
#include <gtest/gtest.h>

#include <atomic>
#include <cstring>
#include <string>
#include <thread>

#include "chimera/chimera.h"
#include "ipc/backplane/backplane.hpp"
#include "ipc/svar/svar.hpp"
#include "../ipc/ipc_fixture.hpp"
#include "../ipc/rtpu_child.hpp"

using namespace chm::test;
namespace bp = chm::bp;
namespace sv = chm::ipc::svar;

namespace {

class Svar : public IpcTest {
protected:
    void SetUp() override {
        IpcTest::SetUp();
        create();
        ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0) << chm_bp_last_error();
    }
    static int declare(const char* name, chm_svar_type_t t, uint32_t rows, uint32_t cols, const char* unit = "") {
        chm_svar_decl_t d{name, t, rows, cols, unit};
        return chm_svar_declare(&d);
    }
    static std::string err() { return chm_bp_last_error(); }
};

// The shared entry of `name`, for tests that play a corrupt or dying peer.
sv::Entry* entry_of(const char* name) {
    sv::Table t;
    if (sv::open_table(false, &t)) return nullptr;
    sv::EntryView v;
    char why[200];
    const int i = sv::find(t, name, &v, why, sizeof why);
    return i >= 0 ? t.entry(std::uint32_t(i)) : nullptr;
}

TEST_F(Svar, DeclareDescribesAndListsVariables) {
    EXPECT_EQ(chm_svar_count(), 0);  // no table yet: nothing declared
    ASSERT_EQ(declare("q", CHM_SVAR_DOUBLE, 6, 1, "rad"), 0) << err();
    ASSERT_EQ(declare("J", CHM_SVAR_FLOAT, 6, 6), 0) << err();
    ASSERT_EQ(declare("gripper_closed", CHM_SVAR_BOOL, 1, 1), 0) << err();
    EXPECT_EQ(declare("q", CHM_SVAR_DOUBLE, 6, 1, "rad"), 0) << "the same declaration again is a no-op";
    EXPECT_EQ(chm_svar_count(), 3);
    chm_svar_info_t i;
    ASSERT_EQ(chm_svar_info("J", &i), 0);
    EXPECT_STREQ(i.name, "J");
    EXPECT_EQ(i.type, CHM_SVAR_FLOAT);
    EXPECT_EQ(i.rows, 6u);
    EXPECT_EQ(i.cols, 6u);
    EXPECT_EQ(i.bytes, 6u * 6u * 4u);
    EXPECT_EQ(i.writes, 0u);
    EXPECT_EQ(i.has_writer, 0);
    ASSERT_EQ(chm_svar_info_at(2, &i), 0);
    EXPECT_STREQ(i.name, "gripper_closed");
    EXPECT_EQ(i.bytes, 1u);
    ASSERT_EQ(chm_svar_info_at(0, &i), 0);
    EXPECT_STREQ(i.unit, "rad");
    EXPECT_EQ(chm_svar_info_at(3, &i), -ENOENT);
    EXPECT_EQ(chm_svar_info("nope", &i), -ENOENT);
    double q[6] = {1, 1, 1, 1, 1, 1};
    ASSERT_EQ(chm_svar_get("q", q, sizeof q), 0);
    for (double x : q) EXPECT_EQ(x, 0.0) << "a new variable starts at zero";
    EXPECT_EQ(chm_svar_get("q", q, sizeof q - 1), -EMSGSIZE);
}

TEST_F(Svar, ConflictingOrBadDeclarationsAreRefusedByName) {
    ASSERT_EQ(declare("q", CHM_SVAR_DOUBLE, 6, 1, "rad"), 0);
    EXPECT_EQ(declare("q", CHM_SVAR_DOUBLE, 7, 1, "rad"), -EEXIST);
    EXPECT_NE(err().find("q is declared as double 6x1 [rad]; this declaration says double 7x1 [rad]"),
              std::string::npos) << err();
    EXPECT_EQ(declare("q", CHM_SVAR_FLOAT, 6, 1, "rad"), -EEXIST);
    EXPECT_EQ(declare("q", CHM_SVAR_DOUBLE, 6, 1, "deg"), -EEXIST);
    EXPECT_EQ(declare("bad", chm_svar_type_t(9), 1, 1), -EINVAL);
    EXPECT_EQ(declare("bad", CHM_SVAR_DOUBLE, 0, 1), -EINVAL);
    EXPECT_EQ(declare("bad", CHM_SVAR_DOUBLE, 65537, 1), -EINVAL);
    EXPECT_EQ(declare("", CHM_SVAR_DOUBLE, 1, 1), -EINVAL);
    EXPECT_EQ(declare("a_name_that_is_longer_than_31_chars", CHM_SVAR_DOUBLE, 1, 1), -ENAMETOOLONG);
    EXPECT_EQ(declare("u", CHM_SVAR_DOUBLE, 1, 1, "a unit too long!"), -ENAMETOOLONG);
    EXPECT_EQ(chm_svar_declare(nullptr), -EINVAL);
    EXPECT_EQ(chm_svar_count(), 1) << "nothing refused was declared";
}

TEST_F(Svar, TheTableFillsUpWithAClearError) {
    int declared = 0, r = 0;
    char name[32];
    while (r == 0 && declared < 1000) {
        std::snprintf(name, sizeof name, "v%d", declared);
        r = declare(name, CHM_SVAR_DOUBLE, 16, 1);
        if (r == 0) ++declared;
    }
    EXPECT_EQ(r, -ENOSPC) << err();
    EXPECT_GT(declared, 0);
    EXPECT_EQ(chm_svar_count(), declared);
}

TEST_F(Svar, SetsCopyWholeVariablesInAndOut) {
    ASSERT_EQ(declare("q", CHM_SVAR_DOUBLE, 3, 1), 0);
    ASSERT_EQ(declare("mode", CHM_SVAR_INT32, 1, 1), 0);
    const char* outs[] = {"q", "mode"};
    const char* ins[] = {"q", "mode"};
    chm_svar_set_t *w = nullptr, *r = nullptr;
    ASSERT_EQ(chm_svar_set_create("writer", nullptr, 0, outs, 2, &w), 0) << err();
    ASSERT_EQ(chm_svar_set_create("reader", ins, 2, nullptr, 0, &r), 0) << err();
    auto* wq = static_cast<double*>(chm_svar_set_local(w, "q"));
    auto* rq = static_cast<double*>(chm_svar_set_local(r, "q"));
    ASSERT_NE(wq, nullptr);
    ASSERT_NE(rq, nullptr);
    EXPECT_EQ(reinterpret_cast<std::uintptr_t>(wq) % 16, 0u);
    EXPECT_EQ(chm_svar_set_local(w, "nope"), nullptr);
    wq[0] = 1.5, wq[1] = -2, wq[2] = 3;
    *static_cast<int32_t*>(chm_svar_set_local(w, "mode")) = 42;
    EXPECT_EQ(rq[0], 0.0) << "the local copy changes only by copy-in";
    ASSERT_EQ(chm_svar_set_write(w), 0);
    EXPECT_EQ(rq[0], 0.0);
    ASSERT_EQ(chm_svar_set_read(r), 0);
    EXPECT_EQ(rq[0], 1.5);
    EXPECT_EQ(rq[1], -2.0);
    EXPECT_EQ(rq[2], 3.0);
    EXPECT_EQ(*static_cast<int32_t*>(chm_svar_set_local(r, "mode")), 42);
    size_t in = 1, out = 1;
    ASSERT_EQ(chm_svar_set_bytes(w, &in, &out), 0);
    EXPECT_EQ(in, 0u);
    EXPECT_EQ(out, 3 * 8u + 4u);
    ASSERT_EQ(chm_svar_set_bytes(r, &in, &out), 0);
    EXPECT_EQ(in, 28u);
    EXPECT_EQ(out, 0u);
    chm_svar_info_t i;
    ASSERT_EQ(chm_svar_info("q", &i), 0);
    EXPECT_EQ(i.writes, 1u);
    EXPECT_EQ(i.has_writer, 1);
    EXPECT_STREQ(i.writer, "writer");
    // A set created later starts from the current value.
    chm_svar_set_t* late = nullptr;
    ASSERT_EQ(chm_svar_set_create("late", ins, 1, nullptr, 0, &late), 0);
    EXPECT_EQ(static_cast<double*>(chm_svar_set_local(late, "q"))[2], 3.0);
    EXPECT_EQ(chm_svar_set_destroy(late), 0);
    EXPECT_EQ(chm_svar_set_destroy(w), 0);
    EXPECT_EQ(chm_svar_set_destroy(r), 0);
    ASSERT_EQ(chm_svar_info("q", &i), 0);
    EXPECT_EQ(i.has_writer, 0);
}

TEST_F(Svar, BadSetsAreRefusedAndLeaveNothing) {
    ASSERT_EQ(declare("a", CHM_SVAR_DOUBLE, 1, 1), 0);
    ASSERT_EQ(declare("b", CHM_SVAR_DOUBLE, 1, 1), 0);
    chm_svar_set_t* s = nullptr;
    const char* ab[] = {"a", "b"};
    const char* aa[] = {"a", "a"};
    const char* an[] = {"a", "nope"};
    EXPECT_EQ(chm_svar_set_create("m", aa, 2, nullptr, 0, &s), -EINVAL);
    EXPECT_EQ(chm_svar_set_create("m", ab, 1, ab, 1, &s), -EINVAL) << "a is both input and output";
    EXPECT_NE(err().find("a is listed twice"), std::string::npos) << err();
    EXPECT_EQ(chm_svar_set_create("m", nullptr, 0, an, 2, &s), -ENOENT);
    EXPECT_NE(err().find("\"nope\""), std::string::npos) << err();
    chm_svar_info_t i;
    ASSERT_EQ(chm_svar_info("a", &i), 0);
    EXPECT_EQ(i.has_writer, 0) << "a refused set claims nothing";
    EXPECT_EQ(chm_svar_set_create(nullptr, ab, 1, nullptr, 0, &s), -EINVAL);
    EXPECT_EQ(chm_svar_set_create("m", ab, 1, nullptr, 0, nullptr), -EINVAL);
    EXPECT_EQ(chm_svar_set_create("an_owner_name_longer_than_31_chars", ab, 1, nullptr, 0, &s), -ENAMETOOLONG);
    EXPECT_EQ(chm_svar_set_read(nullptr), -EINVAL);
    EXPECT_EQ(chm_svar_set_write(nullptr), -EINVAL);
    EXPECT_EQ(chm_svar_set_destroy(nullptr), -EINVAL);
}

TEST_F(Svar, ASecondWriterIsRefusedNamingBoth) {
    ASSERT_EQ(declare("tau", CHM_SVAR_DOUBLE, 6, 1, "N.m"), 0);
    ASSERT_EQ(declare("x", CHM_SVAR_DOUBLE, 1, 1), 0);
    const char* tau[] = {"tau"};
    const char* x_tau[] = {"x", "tau"};
    chm_svar_set_t *pd = nullptr, *grav = nullptr;
    ASSERT_EQ(chm_svar_set_create("joint_pd", nullptr, 0, tau, 1, &pd), 0);
    EXPECT_EQ(chm_svar_set_create("gravity_comp", nullptr, 0, x_tau, 2, &grav), -EBUSY);
    EXPECT_NE(err().find("gravity_comp: state variable tau is written by joint_pd already"), std::string::npos) << err();
    chm_svar_info_t i;
    ASSERT_EQ(chm_svar_info("x", &i), 0);
    EXPECT_EQ(i.has_writer, 0) << "all outputs or none";
    ASSERT_EQ(chm_svar_set_destroy(pd), 0);
    ASSERT_EQ(chm_svar_set_create("gravity_comp", nullptr, 0, x_tau, 2, &grav), 0) << err();
    ASSERT_EQ(chm_svar_info("tau", &i), 0);
    EXPECT_STREQ(i.writer, "gravity_comp");
    EXPECT_EQ(chm_svar_set_destroy(grav), 0);
}

// A module's set: opened at spawn without a claim, claimed when it goes
// on, handed over in a switch (displacing the module going off, which may
// finish its cycle), released when it goes off.
TEST_F(Svar, OpenedSetsClaimLaterAndHandOver) {
    ASSERT_EQ(declare("tau", CHM_SVAR_DOUBLE, 2, 1), 0);
    const char* tau[] = {"tau"};
    chm_svar_set_t *pd = nullptr, *force = nullptr, *other = nullptr;
    ASSERT_EQ(chm_svar_set_open("joint_pd", nullptr, 0, tau, 1, &pd), 0);
    ASSERT_EQ(chm_svar_set_open("force_ctl", nullptr, 0, tau, 1, &force), 0) << "opening claims nothing";
    ASSERT_EQ(chm_svar_set_open("other", nullptr, 0, tau, 1, &other), 0);
    EXPECT_EQ(chm_svar_set_write(pd), -EPERM) << "no write without a claim";
    ASSERT_EQ(chm_svar_set_claim(pd, nullptr, 0), 0) << err();
    EXPECT_EQ(chm_svar_set_claim(pd, nullptr, 0), 0) << "claiming again is a no-op";
    EXPECT_EQ(chm_svar_set_claim(force, nullptr, 0), -EBUSY);
    const char* wrong[] = {"other"};
    EXPECT_EQ(chm_svar_set_claim(force, wrong, 1), -EBUSY) << "only the named writer is displaced";
    const char* off[] = {"joint_pd"};
    ASSERT_EQ(chm_svar_set_claim(force, off, 1), 0) << err();
    chm_svar_info_t i;
    ASSERT_EQ(chm_svar_info("tau", &i), 0);
    EXPECT_STREQ(i.writer, "force_ctl");
    static_cast<double*>(chm_svar_set_local(pd, "tau"))[0] = 1;
    EXPECT_EQ(chm_svar_set_write(pd), 0) << "the displaced writer finishes its cycle";
    ASSERT_EQ(chm_svar_set_release(pd), 0);
    ASSERT_EQ(chm_svar_info("tau", &i), 0);
    EXPECT_STREQ(i.writer, "force_ctl") << "releasing a displaced claim leaves the new writer's";
    ASSERT_EQ(chm_svar_set_release(force), 0);
    ASSERT_EQ(chm_svar_info("tau", &i), 0);
    EXPECT_EQ(i.has_writer, 0);
    EXPECT_EQ(chm_svar_set_claim(other, nullptr, 0), 0);
    for (auto* s : {pd, force, other}) EXPECT_EQ(chm_svar_set_destroy(s), 0);
}

TEST_F(Svar, CallsNeedAnAttachment) {
    ASSERT_EQ(declare("a", CHM_SVAR_DOUBLE, 1, 1), 0);
    const char* a[] = {"a"};
    chm_svar_set_t* s = nullptr;
    ASSERT_EQ(chm_svar_set_create("m", a, 1, nullptr, 0, &s), 0);
    ASSERT_EQ(chm_bp_leave(), 0);
    EXPECT_EQ(declare("b", CHM_SVAR_DOUBLE, 1, 1), -ENOTCONN);
    EXPECT_EQ(chm_svar_set_read(s), -ENOTCONN) << "a set outliving its attachment is refused, not followed";
    EXPECT_EQ(chm_svar_set_destroy(s), 0);
}

// A writer's claim ends with its task, however the task ends.
void claim_and_return(void*) {
    const char* outs[] = {"q"};
    chm_svar_set_t* s = nullptr;
    if (chm_svar_set_create("first", nullptr, 0, outs, 1, &s) == 0) *static_cast<double*>(chm_svar_set_local(s, "q")) = 5;
    if (s) (void)chm_svar_set_write(s);
    // returns without destroying the set: the task's end hook drops the claim
}
int g_second = -1;
void claim_after(void*) {
    const char* outs[] = {"q"};
    chm_svar_set_t* s = nullptr;
    g_second = chm_svar_set_create("second", nullptr, 0, outs, 1, &s);
}

TEST_F(Svar, AClaimEndsWithItsTask) {
    ASSERT_EQ(declare("q", CHM_SVAR_DOUBLE, 1, 1), 0);
    const std::string path = path_;
    const pid_t c = spawn([path] {
        const int r = run_rtpu(path, 1, [] {
            return spawn_task(claim_and_return, nullptr, "first", 5) != CHM_TID_NONE &&
                   spawn_task(claim_after, nullptr, "second", 1) != CHM_TID_NONE;
        });
        return r ? r : (g_second == 0 ? 0 : 70);
    });
    EXPECT_EQ(reap(c), 0) << "70: the second writer was refused after the first task ended";
    double q = 0;
    ASSERT_EQ(chm_svar_get("q", &q, sizeof q), 0);
    EXPECT_EQ(q, 5.0);
}

// A writer that dies in the middle of a write: readers keep reading the
// last complete value at once (never a torn one, never blocked), and the
// variable can be written by a new writer as soon as the death is known.
TEST_F(Svar, AWriterDeadMidWriteBlocksNoReaderAndFreesItsClaim) {
    ASSERT_EQ(declare("v", CHM_SVAR_DOUBLE, 64, 1), 0);
    Pipe ready;
    const std::string path = path_;
    const pid_t c = spawn([&, path] {
        if (chm_bp_join(path.c_str(), 2, "dier")) return 1;
        const char* outs[] = {"v"};
        chm_svar_set_t* s = nullptr;
        if (chm_svar_set_create("dier", nullptr, 0, outs, 1, &s)) return 2;
        auto* v = static_cast<double*>(chm_svar_set_local(s, "v"));
        for (int n = 1; n <= 3; ++n) {
            for (int k = 0; k < 64; ++k) v[k] = n;
            (void)chm_svar_set_write(s);
        }
        // Write 4 half done: its buffer marked, half of it overwritten.
        sv::Entry* e = entry_of("v");
        sv::Table t;
        if (!e || sv::open_table(false, &t)) return 3;
        const std::uint32_t n = e->latest.load() + 1, b = n & 1;
        e->bseq[b].store(2 * n + 1);
        auto* buf = reinterpret_cast<double*>(t.base + e->buf + b * e->stride);
        for (int k = 0; k < 32; ++k) buf[k] = 4;
        ready.put('r');
        pause();
        return 4;
    });
    ASSERT_EQ(ready.get(), 'r');
    double v[64];
    ASSERT_EQ(chm_svar_get("v", v, sizeof v), 0) << "a reader is not held up by the writer mid-write";
    for (double x : v) ASSERT_EQ(x, 3.0);
    const char* outs[] = {"v"};
    chm_svar_set_t* s = nullptr;
    EXPECT_EQ(chm_svar_set_create("heir", nullptr, 0, outs, 1, &s), -EBUSY) << "the writer still lives";
    kill9(c);
    ASSERT_EQ(chm_svar_set_create("heir", nullptr, 0, outs, 1, &s), 0) << err();
    auto* mine = static_cast<double*>(chm_svar_set_local(s, "v"));
    EXPECT_EQ(mine[63], 3.0) << "the heir starts from the last complete value";
    for (int k = 0; k < 64; ++k) mine[k] = 5;
    ASSERT_EQ(chm_svar_set_write(s), 0);
    ASSERT_EQ(chm_svar_get("v", v, sizeof v), 0);
    for (double x : v) ASSERT_EQ(x, 5.0);
    EXPECT_EQ(chm_svar_set_destroy(s), 0);
    ASSERT_TRUE(wait_slot_state(2, CHM_BP_DEAD));
    std::string out;
    EXPECT_EQ(bpcheck(path_, &out), 0) << out;
}

TEST_F(Svar, RecoveryDropsADeadDeclarerAndItsClaims) {
    ASSERT_EQ(declare("a", CHM_SVAR_DOUBLE, 4, 1), 0);
    Pipe ready;
    const std::string path = path_;
    const pid_t c = spawn([&, path] {
        if (chm_bp_join(path.c_str(), 3, "dier")) return 1;
        const char* outs[] = {"a"};
        chm_svar_set_t* s = nullptr;
        if (chm_svar_set_create("dier", nullptr, 0, outs, 1, &s)) return 2;
        // Die holding the table lock in the middle of a declaration.
        sv::Table t;
        if (sv::open_table(false, &t) || sv::lock(t)) return 3;
        bp::lock_mark_dirty(&t.hdr()->lock);
        sv::Entry* e = t.entry(t.hdr()->count.load());
        e->state.store(sv::kEntryLive);
        std::strcpy(e->name, "half");
        t.hdr()->data_used.fetch_add(4096);
        ready.put('r');
        pause();
        return 4;
    });
    ASSERT_EQ(ready.get(), 'r');
    kill9(c);
    ASSERT_EQ(declare("b", CHM_SVAR_DOUBLE, 2, 1), 0) << err();
    chm_svar_info_t i;
    EXPECT_EQ(chm_svar_info("half", &i), -ENOENT);
    EXPECT_EQ(entry_of("b")->buf, entry_of("a")->buf + 2 * 32) << "the half declaration's bytes were given back";
    ASSERT_EQ(chm_svar_info("a", &i), 0);
    EXPECT_EQ(i.has_writer, 0);
    ASSERT_TRUE(wait_slot_state(3, CHM_BP_DEAD));
    ASSERT_EQ(chm_svar_info("a", &i), 0);
    EXPECT_EQ(entry_of("a")->writer_token.load(), 0u) << "recovery cleared the dead slot's claim";
    std::string out;
    EXPECT_EQ(bpcheck(path_, &out), 0) << out;
}

TEST_F(Svar, ACorruptTableIsRefusedNamingTheField) {
    ASSERT_EQ(declare("a", CHM_SVAR_DOUBLE, 4, 1), 0);
    sv::Entry* e = entry_of("a");
    ASSERT_NE(e, nullptr);
    const std::uint32_t buf = e->buf;
    e->buf = 0xFFFFFF00u;
    const char* a[] = {"a"};
    chm_svar_set_t* s = nullptr;
    EXPECT_EQ(chm_svar_set_create("m", a, 1, nullptr, 0, &s), -EBADMSG);
    EXPECT_NE(err().find("state variable [0] a: buffer"), std::string::npos) << err();
    double v[4];
    EXPECT_EQ(chm_svar_get("a", v, sizeof v), -EBADMSG);
    EXPECT_EQ(chm_bp_validate(path_.c_str()), -EBADMSG);
    EXPECT_NE(std::string(chm_bp_last_error()).find("chimera.svar"), std::string::npos) << chm_bp_last_error();
    e->buf = buf;
    e->rows = 5;  // bytes no longer match the shape
    EXPECT_EQ(chm_svar_get("a", v, sizeof v), -EBADMSG);
    e->rows = 4;
    // Sequence words that never settle: the read gives up, bounded.
    e->bseq[0].store(1);
    e->bseq[1].store(1);
    EXPECT_EQ(chm_svar_get("a", v, sizeof v), -EAGAIN);
    EXPECT_NE(err().find("changed under every read for 20 ms"), std::string::npos) << err();
    EXPECT_EQ(chm_svar_set_create("m", a, 1, nullptr, 0, &s), -EAGAIN);
    EXPECT_NE(err().find("a changed under every read for 20 ms"), std::string::npos) << err();
    e->latest.store(0);
    e->bseq[0].store(2);
    EXPECT_EQ(chm_svar_get("a", v, sizeof v), 0);
    EXPECT_EQ(chm_bp_validate(path_.c_str()), 0) << chm_bp_last_error();
}

// A set created while its input's writer never pauses: the first copy
// (what a new set's local starts with) may be lapped many times in a row
// by a writer faster than the reader's copy; the creation waits for a
// consistent copy instead of failing.
TEST_F(Svar, ASetCreatedBesideAWriterThatNeverPausesGetsAConsistentCopy) {
    constexpr int kElems = 8;  // one cache line: the writer laps most often (64: half the runs caught)
    ASSERT_EQ(declare("busy", CHM_SVAR_DOUBLE, kElems, 1), 0) << err();
    chm_svar_set_t* w = nullptr;
    const char* outs[] = {"busy"};
    ASSERT_EQ(chm_svar_set_create("writer", nullptr, 0, outs, 1, &w), 0) << err();
    auto* wv = static_cast<double*>(chm_svar_set_local(w, "busy"));
    std::atomic<bool> stop{false};
    std::atomic<std::uint64_t> writes{0};
    std::thread writer([&] {
        for (std::uint64_t n = 1; !stop.load(std::memory_order_relaxed); ++n) {
            for (int k = 0; k < kElems; ++k) wv[k] = double(n);
            (void)chm_svar_set_write(w);
            writes.store(n, std::memory_order_relaxed);
        }
    });
    while (writes.load() < 1000) std::this_thread::yield();  // the writer is at full speed
    int failed = 0, torn = 0, created = 0;
    std::string first_error;
    const char* ins[] = {"busy"};
    for (int i = 0; i < 50000; ++i) {
        chm_svar_set_t* s = nullptr;
        const int r = chm_svar_set_create("reader", ins, 1, nullptr, 0, &s);
        if (r != 0) {
            if (!failed++) first_error = std::to_string(r) + " " + err();
            continue;
        }
        ++created;
        const auto* v = static_cast<const double*>(chm_svar_set_local(s, "busy"));
        for (int k = 1; k < kElems; ++k) torn += v[k] != v[0];
        EXPECT_EQ(chm_svar_set_destroy(s), 0);
    }
    stop = true;
    writer.join();
    std::fprintf(stderr, "%d sets created, %d refused, %d torn\n", created, failed, torn);
    EXPECT_EQ(failed, 0) << first_error;
    EXPECT_EQ(torn, 0);
    EXPECT_EQ(chm_svar_set_destroy(w), 0);
}

}  // namespace
