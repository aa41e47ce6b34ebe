// Issue 15 item 4: every object is checked when it is opened. A real
// backplane holds a shared memory segment, a remote semaphore and a
// message queue with two messages; each case corrupts one field of the
// file (as a stray store or a damaged file would), then attaches and opens
// everything. The attach or the open must answer -EBADMSG with a last
// error naming the field, chm_bp_validate must refuse the file the same
// way, and nothing may crash. Further cases corrupt a queue after its open
// (the data path bounds what it reads) and run the recovery callbacks on
// corrupt entries.
#include <sys/mman.h>

#include <atomic>
#include <functional>
#include <thread>

#include "chimera/msgq.h"
#include "chimera/rsem.h"
#include "chimera/shm.h"
#include "ipc/backplane/backplane.hpp"
#include "ipc/msgq/msgq.hpp"
#include "ipc_fixture.hpp"

namespace chm::test {
namespace {

using ipc::msgq::QueueHeader;
using W = std::atomic<std::uint32_t>;

// Where the objects of the image lie (offsets from the file base).
struct Image {
    char* base = nullptr;
    std::size_t size = 0;
    bp::Layout layout;
    std::uint32_t shm_index = 0, sem_index = 0, q_index = 0;
    std::uint32_t sem_off = 0, q_off = 0;
    bp::RegistryEntry* entry(std::uint32_t i) const {
        return reinterpret_cast<bp::RegistryEntry*>(base + layout.regions[bp::kRegionRegistry].offset) + i;
    }
    bp::RtpuEntry* rtpu(std::uint32_t s) const {
        return reinterpret_cast<bp::RtpuEntry*>(base + layout.regions[bp::kRegionTable].offset) + s;
    }
    bp::RingHeader* ring(std::uint32_t s) const {
        return reinterpret_cast<bp::RingHeader*>(base + layout.regions[bp::kRegionRings].offset + s * layout.ring_stride);
    }
    bp::ArenaHeader* common() const {
        return reinterpret_cast<bp::ArenaHeader*>(base + layout.regions[bp::kRegionCommon].offset);
    }
    QueueHeader* queue() const { return reinterpret_cast<QueueHeader*>(base + q_off); }
    W& hdr_registry_token() const { return reinterpret_cast<bp::Header*>(base)->registry_lock.token; }
    // The semaphore's words (rsem.cpp): lock 16 bytes, then magic, kind,
    // count, nwaiting, seq, broken; then 64 records of 6 words.
    std::uint32_t* sem_words() const {
        return reinterpret_cast<std::uint32_t*>(base + ((sem_off + 63) & ~63u) + 16);
    }
};

// When a corruption must be caught.
enum Stage { kAtAttach, kAtOpen };

struct Case {
    const char* what;
    Stage stage;
    const char* expect;  // in chm_bp_last_error()
    std::function<void(const Image&)> corrupt;
};

class IpcValidate : public IpcTest {
protected:
    // The backplane with its three objects, left quiescent (no process
    // attached), mapped read-write into `img_` without the library.
    void build() {
        create();
        ASSERT_EQ(chm_bp_attach_host(path_.c_str(), "builder", nullptr), 0) << chm_bp_last_error();
        void* seg = nullptr;
        ASSERT_EQ(chm_shm_create("seg", 512, CHM_SHM_COMMON, &seg), 0) << chm_bp_last_error();
        chm_rsem_t* sem = nullptr;
        ASSERT_EQ(chm_rsem_create("sem", CHM_SEM_COUNTING, 1, CHM_SHM_COMMON, &sem), 0) << chm_bp_last_error();
        chm_msgq_attr_t attr;
        chm_msgq_attr_init(&attr);
        attr.order = CHM_MSGQ_PRIORITY;
        attr.max_msg = 16;
        attr.max_count = 4;
        chm_msgq_t* q = nullptr;
        ASSERT_EQ(chm_msgq_create("q", &attr, CHM_MSGQ_COMMON, &q), 0) << chm_bp_last_error();
        const std::uint32_t one = 1, two = 2;
        ASSERT_EQ(chm_msgq_try_send(q, 0, 3, &one, sizeof one), 0);
        ASSERT_EQ(chm_msgq_try_send(q, 0, 7, &two, sizeof two), 0);
        const bp::Attachment* a = bp::current();
        bp::EntryInfo e{};
        ASSERT_EQ(bp::registry_lookup(*a, "seg", bp::kKindShm, &e), 0);
        img_.shm_index = e.index;
        ASSERT_EQ(bp::registry_lookup(*a, "sem", bp::kKindRemoteSem, &e), 0);
        img_.sem_index = e.index;
        img_.sem_off = e.offset;
        ASSERT_EQ(bp::registry_lookup(*a, "q", bp::kKindMsgQueue, &e), 0);
        img_.q_index = e.index;
        img_.q_off = e.offset;
        img_.layout = a->layout;
        img_.size = a->size;
        ASSERT_EQ(chm_bp_leave(), 0);
        const int fd = open(path_.c_str(), O_RDWR);
        ASSERT_GE(fd, 0);
        void* p = mmap(nullptr, img_.size, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
        close(fd);
        ASSERT_NE(p, MAP_FAILED);
        img_.base = static_cast<char*>(p);
    }
    void TearDown() override {
        if (img_.base) munmap(img_.base, img_.size);
        img_.base = nullptr;
        IpcTest::TearDown();
    }
    // chm_bp_validate of the file, 3,000 times or for 2 s: how many refused
    // it, and the first refusal's text.
    struct Checks {
        int checks = 0, refused = 0;
        std::string first;
    };
    Checks check_repeatedly() {
        Checks c;
        const std::uint64_t end = now_ns() + 2'000'000'000ull;
        for (; c.checks < 3000 && now_ns() < end; ++c.checks)
            if (chm_bp_validate(path_.c_str()) != 0 && c.refused++ == 0) c.first = chm_bp_last_error();
        return c;
    }
    // Attach and open every object: the first failing status, its text.
    int attach_and_open(std::string* why) {
        int r = chm_bp_attach_host(path_.c_str(), "opener", nullptr);
        if (r == 0) {
            void* seg = nullptr;
            chm_rsem_t* sem = nullptr;
            chm_msgq_t* q = nullptr;
            if ((r = chm_shm_attach("seg", &seg, nullptr)) == 0 && (r = chm_rsem_open("sem", &sem)) == 0)
                r = chm_msgq_open("q", &q);
        }
        *why = chm_bp_last_error();
        (void)chm_bp_leave();
        return r;
    }
    void run(const Case& c) {
        SCOPED_TRACE(c.what);
        build();
        if (HasFatalFailure()) return;
        // The untouched image opens: the corruption alone makes it fail.
        std::string why;
        ASSERT_EQ(attach_and_open(&why), 0) << why;
        c.corrupt(img_);
        EXPECT_EQ(chm_bp_validate(path_.c_str()), -EBADMSG);
        EXPECT_NE(std::string(chm_bp_last_error()).find(c.expect), std::string::npos) << chm_bp_last_error();
        const int r = attach_and_open(&why);
        EXPECT_EQ(r, -EBADMSG) << why;
        EXPECT_NE(why.find(c.expect), std::string::npos) << why;
        if (c.stage == kAtAttach) {
            EXPECT_NE(why.find("backplane "), std::string::npos) << why;
        }
        munmap(img_.base, img_.size);
        img_ = Image{};
        (void)chm_bp_leave();
        remove_dir();
        dir_ = make_private_dir("chm-ipc-");
        path_ = dir_ + "/test.bp";
    }
    Image img_;
};

void poke(W& w, std::uint32_t v) { w.store(v); }

// A checker walks a live queue's lists without its lock: a send or receive
// landing during the walk must not read as corruption (it did: "count is
// 1, the lists hold 0" from chimera status beside a running demo).
TEST_F(IpcValidate, ALiveQueueInUseIsNeverReportedCorrupt) {
    create();
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), "user", nullptr), 0) << chm_bp_last_error();
    chm_msgq_attr_t attr;
    chm_msgq_attr_init(&attr);
    attr.max_msg = 16;
    attr.max_count = 4;
    chm_msgq_t* q = nullptr;
    ASSERT_EQ(chm_msgq_create("busy", &attr, CHM_MSGQ_COMMON, &q), 0) << chm_bp_last_error();
    std::atomic<bool> stop{false};
    std::atomic<std::uint64_t> moved{0};
    std::thread user([&] {
        std::uint32_t v = 0, got = 0;
        while (!stop.load()) {
            if (chm_msgq_try_send(q, 0, 0, &v, sizeof v) == 0) ++v;
            if (chm_msgq_try_receive(q, &got, sizeof got, nullptr) >= 0) moved.fetch_add(1);
        }
    });
    std::thread waiter([&] {  // a waiter record taken, granted or withdrawn at its timeout
        std::uint32_t got = 0;
        while (!stop.load())
            if (chm_msgq_receive_timed(q, &got, sizeof got, nullptr, 100'000) >= 0) moved.fetch_add(1);
    });
    const Checks c = check_repeatedly();
    stop.store(true);
    user.join();
    waiter.join();
    EXPECT_GT(moved.load(), 100u) << "the queue was not in use";
    EXPECT_EQ(c.refused, 0) << "of " << c.checks << " checks; the first: " << c.first;
    EXPECT_EQ(chm_msgq_close(q), 0);
    EXPECT_EQ(chm_bp_leave(), 0);
}

// The same for a remote semaphore whose waiter records come and go.
TEST_F(IpcValidate, ALiveSemaphoreInUseIsNeverReportedCorrupt) {
    create();
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), "user", nullptr), 0) << chm_bp_last_error();
    chm_rsem_t* sem = nullptr;
    ASSERT_EQ(chm_rsem_create("busy", CHM_SEM_COUNTING, 0, CHM_SHM_COMMON, &sem), 0) << chm_bp_last_error();
    std::atomic<bool> stop{false};
    std::atomic<std::uint64_t> taken{0};
    std::thread waiter([&] {  // blocks in P: a waiting record, granted, freed
        while (!stop.load())
            if (chm_rsem_p_timed(sem, 50'000'000) == 0) taken.fetch_add(1);
    });
    std::thread giver([&] {
        while (!stop.load())
            if (chm_rsem_value(sem) == 0) (void)chm_rsem_v(sem);
    });
    const Checks c = check_repeatedly();
    stop.store(true);
    (void)chm_rsem_v(sem);
    waiter.join();
    giver.join();
    EXPECT_GT(taken.load(), 100u) << "the semaphore was not in use";
    EXPECT_EQ(c.refused, 0) << "of " << c.checks << " checks; the first: " << c.first;
    EXPECT_EQ(chm_rsem_close(sem), 0);
    EXPECT_EQ(chm_bp_leave(), 0);
}

TEST_F(IpcValidate, ACorruptStructureIsRefusedAtAttachNamingTheField) {
    const Case cases[] = {
        {"ring capacity 0", kAtAttach, "ring[1].capacity", [](const Image& i) { i.ring(1)->capacity = 0; }},
        {"ring record size 0", kAtAttach, "ring[2].record_size", [](const Image& i) { i.ring(2)->record_size = 0; }},
        {"ring record size too big", kAtAttach, "ring[0].record_size", [](const Image& i) { i.ring(0)->record_size = 1u << 30; }},
        {"slot state", kAtAttach, "rtpu[3].status", [](const Image& i) { poke(i.rtpu(3)->status, 9); }},
        {"slot kind", kAtAttach, "rtpu[4].kind", [](const Image& i) { poke(i.rtpu(4)->kind, 7); }},
        {"common arena self", kAtAttach, "common arena.self", [](const Image& i) { i.common()->self += 16; }},
        {"common arena size", kAtAttach, "common arena.size", [](const Image& i) { i.common()->size = 0xFFFFFFF0u; }},
        {"entry offset past the arena", kAtAttach, "].offset",
         [](const Image& i) { poke(i.entry(i.shm_index)->offset, 0xFFFFFF00u); }},
        {"entry offset + size wraps 32 bits", kAtAttach, "].offset",
         [](const Image& i) { poke(i.entry(i.shm_index)->size, 0xFFFFFFF0u); }},
        {"entry not an allocated block", kAtAttach, "is not an allocated block",
         [](const Image& i) { poke(i.entry(i.sem_index)->offset, i.entry(i.sem_index)->offset.load() + 16); }},
        {"entry where", kAtAttach, "].where is 77", [](const Image& i) { poke(i.entry(i.q_index)->where, 77); }},
        {"entry kind", kAtAttach, "].kind is 40", [](const Image& i) { poke(i.entry(i.q_index)->kind, 40); }},
        {"entry state", kAtAttach, "].state is 5", [](const Image& i) { poke(i.entry(i.q_index)->state, 5); }},
    };
    for (const Case& c : cases) {
        run(c);
        if (HasFatalFailure()) return;
    }
}

TEST_F(IpcValidate, ACorruptObjectIsRefusedAtOpenNamingTheField) {
    constexpr std::uint32_t kNil = ipc::msgq::kNil;
    const Case cases[] = {
        {"queue free_head", kAtOpen, "free_head is 1000", [](const Image& i) { poke(i.queue()->free_head, 1000); }},
        {"queue head", kAtOpen, "head[7] is 4096", [](const Image& i) { poke(i.queue()->head(7), 4096); }},
        {"queue tail", kAtOpen, "tail[3] is 9", [](const Image& i) { poke(i.queue()->tail(3), 9); }},
        {"queue list emptied, level_mask not", kAtOpen, "tail[7]",
         [](const Image& i) { poke(i.queue()->tail(7), kNil); poke(i.queue()->head(7), kNil); }},
        {"queue max_count 0", kAtOpen, "max_count is 0", [](const Image& i) { i.queue()->max_count = 0; }},
        {"queue max_count huge", kAtOpen, "max_count is", [](const Image& i) { i.queue()->max_count = 0x7FFFFFFF; }},
        {"queue max_msg 0", kAtOpen, "max_msg is 0", [](const Image& i) { i.queue()->max_msg = 0; }},
        {"queue slot_size", kAtOpen, "slot_size is 8", [](const Image& i) { i.queue()->slot_size = 8; }},
        {"queue slots_off", kAtOpen, "slots_off is", [](const Image& i) { i.queue()->slots_off = 0xFFFFFF00u; }},
        {"queue waiters_off", kAtOpen, "waiters_off is", [](const Image& i) { i.queue()->waiters_off += 4096; }},
        {"queue total_size", kAtOpen, "total_size", [](const Image& i) { i.queue()->total_size = 0x10000000; }},
        {"queue order", kAtOpen, "order is 9", [](const Image& i) { i.queue()->order = 9; }},
        {"queue count", kAtOpen, "count is 3", [](const Image& i) { poke(i.queue()->count, 3); }},
        {"queue slot len", kAtOpen, "len 4000",
         [](const Image& i) {
             const QueueHeader* q = i.queue();
             const std::uint32_t h = q->head(7).load();
             auto* s = reinterpret_cast<ipc::msgq::MsgSlot*>(i.base + i.q_off + q->slots_off + h * q->slot_size);
             poke(s->len, 4000);
         }},
        {"queue waiter state", kAtOpen, "waiter 2: state 9",
         [](const Image& i) {
             const QueueHeader* q = i.queue();
             poke(reinterpret_cast<ipc::msgq::Waiter*>(i.base + i.q_off + q->waiters_off)[2].state, 9);
         }},
        {"semaphore kind", kAtOpen, "kind is 7", [](const Image& i) { i.sem_words()[1] = 7; }},
        {"semaphore nwaiting", kAtOpen, "nwaiting is 70", [](const Image& i) { i.sem_words()[3] = 70; }},
        {"semaphore record state", kAtOpen, "waiter 5: state 6", [](const Image& i) { i.sem_words()[6 + 5 * 6] = 6; }},
        {"semaphore magic", kAtOpen, "magic is", [](const Image& i) { i.sem_words()[0] = 0; }},
        {"queue entry too small", kAtOpen, "smaller than",
         [](const Image& i) { poke(i.entry(i.q_index)->size, 64); }},
    };
    for (const Case& c : cases) {
        run(c);
        if (HasFatalFailure()) return;
    }
}

TEST_F(IpcValidate, ALockNamingTheJoinersNewGenerationIsRefused) {
    build();
    ASSERT_FALSE(HasFatalFailure());
    // Slot 0 "running" in a process that is gone: the monitor recovers it
    // at once, and its recovery waits for the registry lock, which names
    // the generation the next host attach (slot 7) is about to take. No
    // process can hold that token: before this check the recovery waited
    // for it for ever and the leave never returned.
    const pid_t gone = spawn([] { return 0; });
    ASSERT_EQ(reap(gone), 0);
    poke(img_.rtpu(0)->pid, std::uint32_t(gone));
    poke(img_.rtpu(0)->kind, 1);
    poke(img_.rtpu(0)->status, bp::make_status(5, bp::SlotState::Running));
    const std::uint32_t next = bp::status_gen(img_.rtpu(7)->status.load()) + 1;
    poke(img_.hdr_registry_token(), bp::make_token(7, next));
    EXPECT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), -EBADMSG);
    EXPECT_NE(std::string(chm_bp_last_error()).find("header.registry_lock.token"), std::string::npos)
        << chm_bp_last_error();
    EXPECT_EQ(bp::status_state(img_.rtpu(7)->status.load()), bp::SlotState::Free);  // the join was undone
}

TEST_F(IpcValidate, ACorruptArenaIsRefusedWhenItIsUsed) {
    build();
    ASSERT_FALSE(HasFatalFailure());
    // The first free block of common memory: size 0 (an endless walk) and
    // then a free list pointing outside the arena.
    bp::ArenaHeader* c = img_.common();
    const std::uint32_t f = c->free_head.load();
    ASSERT_NE(f, 0u);
    auto* b = reinterpret_cast<bp::BlockHeader*>(img_.base + f);
    const std::uint32_t saved = b->size_flags.load();
    poke(b->size_flags, 0);
    EXPECT_EQ(chm_bp_validate(path_.c_str()), -EBADMSG);
    EXPECT_NE(std::string(chm_bp_last_error()).find("common arena block at"), std::string::npos) << chm_bp_last_error();
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0) << chm_bp_last_error();
    void* seg = nullptr;
    EXPECT_EQ(chm_shm_create("more", 64, CHM_SHM_COMMON, &seg), -EBADMSG);
    EXPECT_NE(std::string(chm_bp_last_error()).find("size 0 does not fit"), std::string::npos) << chm_bp_last_error();
    poke(b->size_flags, saved);
    poke(c->free_head, 0xFFFFFFF0u);
    EXPECT_EQ(chm_shm_create("more", 64, CHM_SHM_COMMON, &seg), -EBADMSG);
    EXPECT_NE(std::string(chm_bp_last_error()).find("free_head list"), std::string::npos) << chm_bp_last_error();
    poke(c->free_head, f);
    EXPECT_EQ(chm_shm_create("more", 64, CHM_SHM_COMMON, &seg), 0) << chm_bp_last_error();
}

TEST_F(IpcValidate, TheDataPathBoundsWhatItReadsAfterTheOpen) {
    build();
    ASSERT_FALSE(HasFatalFailure());
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0) << chm_bp_last_error();
    chm_msgq_t* q = nullptr;
    ASSERT_EQ(chm_msgq_open("q", &q), 0) << chm_bp_last_error();
    QueueHeader* h = img_.queue();
    // A header whose geometry changed after the open is not followed: the
    // calls use the geometry the open checked.
    h->slots_off = 0x7FFFFF00u;
    h->slot_size = 0x100000;
    h->max_count = 1u << 20;
    std::uint32_t v = 0;
    chm_msgq_msg_info_t info{};
    EXPECT_EQ(chm_msgq_try_receive(q, &v, sizeof v, &info), int(sizeof v)) << chm_bp_last_error();
    EXPECT_EQ(v, 2u);  // priority 7 first
    chm_msgq_info_t st{};
    ASSERT_EQ(chm_msgq_info(q, &st), 0);
    EXPECT_EQ(st.attr.max_count, 4u);
    // Indices out of range: one compare each, -EBADMSG naming the field.
    const std::uint32_t fh = h->free_head.load();
    poke(h->free_head, 4);
    EXPECT_EQ(chm_msgq_try_send(q, 0, 1, &v, sizeof v), -EBADMSG);
    EXPECT_NE(std::string(chm_bp_last_error()).find("free_head is 4"), std::string::npos) << chm_bp_last_error();
    poke(h->free_head, fh);
    const std::uint32_t hd = h->head(3).load();
    poke(h->head(3), 0xFFFF0000u);
    EXPECT_EQ(chm_msgq_try_receive(q, &v, sizeof v, nullptr), -EBADMSG);
    EXPECT_NE(std::string(chm_bp_last_error()).find("head[3] is 4294901760"), std::string::npos) << chm_bp_last_error();
    poke(h->head(3), hd);
    auto* s = reinterpret_cast<ipc::msgq::MsgSlot*>(reinterpret_cast<char*>(h) + sizeof(QueueHeader) + hd * 48);
    poke(s->len, 1u << 24);
    EXPECT_EQ(chm_msgq_try_receive(q, &v, sizeof v, nullptr), -EBADMSG);
    EXPECT_NE(std::string(chm_bp_last_error()).find("len 16777216 above max_msg 16"), std::string::npos) << chm_bp_last_error();
    poke(s->len, sizeof v);
    EXPECT_EQ(chm_msgq_try_receive(q, &v, sizeof v, nullptr), int(sizeof v)) << chm_bp_last_error();
    EXPECT_EQ(v, 1u);
    // A handle this process closed no longer resolves.
    ASSERT_EQ(chm_msgq_close(q), 0);
    EXPECT_EQ(chm_msgq_try_send(q, 0, 1, &v, sizeof v), -EINVAL);
}

TEST_F(IpcValidate, RecoveryDoesNotFollowACorruptEntry) {
    build();
    ASSERT_FALSE(HasFatalFailure());
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0) << chm_bp_last_error();
    const bp::Attachment& a = *bp::current();
    // The recovery callbacks of a dead slot 5 run over entries whose
    // offsets and geometry were damaged after the attach: they must leave
    // them alone, not read through them.
    ASSERT_EQ(bp::registry_lock(a, a.token), 0);
    poke(img_.entry(img_.sem_index)->offset, 0xFFFFFF00u);
    ipc::rsem_recover(a, img_.sem_index, 5, 1, a.token);
    poke(img_.entry(img_.q_index)->offset, 0xFFFFFE00u);
    ipc::msgq::recover(a, img_.q_index, 5, 1, a.token);
    poke(img_.entry(img_.q_index)->offset, img_.q_off);
    img_.queue()->waiters_off = 0x7FFFFFF0u;
    ipc::msgq::recover(a, img_.q_index, 5, 1, a.token);
    bp::registry_unlock(a);
    chm_rsem_t* sem = nullptr;
    EXPECT_EQ(chm_rsem_open("sem", &sem), -EBADMSG);
    chm_msgq_t* q = nullptr;
    EXPECT_EQ(chm_msgq_open("q", &q), -EBADMSG);
    EXPECT_NE(std::string(chm_bp_last_error()).find("waiters_off"), std::string::npos) << chm_bp_last_error();
}

}  // namespace
}  // namespace chm::test
