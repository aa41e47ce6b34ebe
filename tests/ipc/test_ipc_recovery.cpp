// Death and recovery: a process killed with SIGKILL is detected quickly,
// its slot is recovered and can be joined again at once, the registry lock
// it held is robbed and the registry repaired, its attachments dropped,
// each kind's recovery callback run; the monitor thread never takes the
// kernel's timer signal.
#include <algorithm>
#include <atomic>
#include <fstream>

#include <sys/syscall.h>

#include "chimera/shm.h"
#include "ipc/backplane/backplane.hpp"
#include "ipc_fixture.hpp"
#include "port.hpp"

namespace chm::test {
namespace {

using IpcRecovery = IpcTest;

TEST_F(IpcRecovery, DeathIsDetectedAndTheSlotRecoveredQuickly) {
    create();
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), "watcher", nullptr), 0);
    std::vector<double> ms, after_exit;
    for (int round = 0; round < 10; ++round) {
        Pipe ready;
        const pid_t c = spawn([&] {
            if (chm_bp_join(path_.c_str(), 3, nullptr)) return 1;
            ready.put('r');
            pause();
            return 2;
        });
        ASSERT_EQ(ready.get(), 'r');
        ASSERT_TRUE(wait_slot_state(3, CHM_BP_RUNNING));
        sleep_us(30000);  // steady state: the monitor scans new peers every 10 ms
        // Our own pidfd tells when the kernel has finished the exit (the
        // teardown of the child's memory takes milliseconds by itself).
        const int pfd = int(syscall(SYS_pidfd_open, c, 0));
        const std::uint64_t t0 = now_ns();
        kill(c, SIGKILL);  // not reaped yet: a zombie must count as dead too
        pollfd pf{pfd, POLLIN, 0};
        const bool exited = pfd >= 0 && poll(&pf, 1, 2000) == 1;
        const std::uint64_t t1 = now_ns();
        ASSERT_TRUE(wait_slot_state(3, CHM_BP_DEAD, 2000)) << "round " << round;
        ms.push_back((now_ns() - t0) / 1e6);
        if (exited) after_exit.push_back((now_ns() - t1) / 1e6);
        if (pfd >= 0) close(pfd);
        EXPECT_EQ(reap(c), -SIGKILL);
    }
    std::sort(ms.begin(), ms.end());
    std::sort(after_exit.begin(), after_exit.end());
    std::printf("kill -9 to slot DEAD (detected and recovered): median %.2f ms, worst %.2f ms of %zu\n",
                ms[ms.size() / 2], ms.back(), ms.size());
    if (!after_exit.empty())
        std::printf("  of which after the kernel finished the exit: median %.3f ms, worst %.3f ms\n",
                    after_exit[after_exit.size() / 2], after_exit.back());
    chm_bp_status_t st;
    ASSERT_EQ(chm_bp_status(&st), 0);
    EXPECT_EQ(st.recoveries, 10u);
    EXPECT_EQ(st.slot[3].pid, 0);
    EXPECT_EQ(check_now(), "");
}

TEST_F(IpcRecovery, SameRtpuRejoinsAfterKillWithoutCleanup) {
    // Nobody else is attached: the joiner itself finds the dead holder.
    create();
    std::uint32_t gen = 0;
    for (int round = 0; round < 5; ++round) {
        Pipe ready, report;
        const pid_t c = spawn([&] {
            if (chm_bp_join(path_.c_str(), 5, "servo")) return 1;
            chm_bp_status_t st;
            (void)chm_bp_status(&st);
            report.put(char(st.slot[5].generation));
            ready.put('r');
            pause();
            return 2;
        });
        const int g = report.get();
        ASSERT_EQ(ready.get(), 'r');
        ASSERT_GT(g, 0);
        EXPECT_EQ(std::uint32_t(g), gen + 1) << "round " << round;  // +1 per join
        gen = std::uint32_t(g);
        kill9(c);
    }
    ASSERT_EQ(chm_bp_join(path_.c_str(), 5, "servo"), 0) << chm_bp_last_error();
    chm_bp_status_t st;
    ASSERT_EQ(chm_bp_status(&st), 0);
    EXPECT_EQ(st.slot[5].generation, gen + 1);
    EXPECT_EQ(st.recoveries, 5u);
    EXPECT_EQ(check_now(), "");
}

TEST_F(IpcRecovery, RegistryLockHeldByDeadProcessIsRecovered) {
    create();
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0);
    void* keep = nullptr;
    ASSERT_EQ(chm_shm_create("keep", 100, CHM_SHM_COMMON, &keep), 0);
    chm_bp_status_t st;
    ASSERT_EQ(chm_bp_status(&st), 0);
    const std::uint32_t free0 = st.common_free;
    // The named points where the child dies, all with the registry lock held.
    enum Point {
        kJustLocked, kArenaMidSplit, kAllocatedUncommitted, kEntryHalfWritten, kEntryPublishedUncommitted, kPoints
    };
    const int kRepeats = kill_repeats();
    for (int run = 0; run < kPoints * kRepeats; ++run) {
        const int point = run % kPoints;
        SCOPED_TRACE(point);
        Pipe ready;
        const pid_t c = spawn([&] {
            if (chm_bp_join(path_.c_str(), 2, nullptr)) return 1;
            const bp::Attachment& a = *bp::current();
            if (bp::registry_lock(a, a.token)) return 2;
            bp::lock_mark_dirty(&a.hdr()->registry_lock);
            if (point == kArenaMidSplit) {
                // Holding the arena lock, dirty, with a split half done:
                // the tail's header written inside the free block, the
                // block itself not yet shrunk.
                bp::ArenaHeader* ar = a.common_arena();
                if (bp::arena_lock(a, ar, a.token)) return 3;
                bp::lock_mark_dirty(&ar->lock);
                const std::uint32_t b = ar->free_head.load();
                auto* tail = a.at<bp::BlockHeader>(b + 256);
                tail->size_flags = 4096;
                tail->prev_size = 256;
                tail->tag = (b + 256) ^ bp::kBlockTagXor;
            }
            if (point >= kAllocatedUncommitted) {
                bp::ArenaHeader* ar = a.common_arena();
                if (bp::arena_lock(a, ar, a.token)) return 3;
                const std::uint32_t off = bp::arena_alloc_locked(a, ar, 200, a.token);
                bp::arena_unlock(ar);
                if (point >= kEntryHalfWritten) {
                    bp::RegistryEntry* e = a.entry(5);
                    e->seq.fetch_add(1);  // odd: mid-change
                    e->kind = bp::kKindShm;
                    e->offset = off;
                    e->size = 200;
                    e->where = bp::kWhereCommon;
                    e->attached = 1u << a.slot;
                    std::uint32_t w = 0;
                    std::memcpy(&w, "off", 4);
                    e->name_words[0] = w;
                    if (point == kEntryPublishedUncommitted) e->state = std::uint32_t(bp::EntryState::Live);
                }
            }
            ready.put('r');
            pause();
            return 4;
        });
        ASSERT_EQ(ready.get(), 'r');
        kill9(c);
        // Our next registry operation waits for the lock, robs it or
        // finds it already recovered by our monitor thread.
        void* p = nullptr;
        ASSERT_EQ(chm_shm_create("after", 64, CHM_SHM_COMMON, &p), 0) << chm_bp_last_error();
        ASSERT_TRUE(wait_slot_state(2, CHM_BP_DEAD));
        void* off = nullptr;
        if (point == kEntryPublishedUncommitted) {
            // Published before it died: the repair finished the create.
            ASSERT_EQ(chm_shm_attach("off", &off, nullptr), 0);
            EXPECT_EQ(chm_shm_detach(off), 0);
            EXPECT_EQ(chm_shm_destroy("off"), 0);  // nobody holds it now: freed
        } else {
            EXPECT_EQ(chm_shm_attach("off", &off, nullptr), -ENOENT);
        }
        EXPECT_EQ(chm_shm_destroy("after"), 0);
        EXPECT_EQ(chm_shm_detach(p), 0);
        EXPECT_EQ(check_now(), "");
        ASSERT_EQ(chm_bp_status(&st), 0);
        EXPECT_EQ(st.common_free, free0);  // nothing leaked
        EXPECT_EQ(st.objects, 1u);
    }
    std::string out;
    EXPECT_EQ(bpcheck(path_, &out), 0) << out;
}

TEST_F(IpcRecovery, KilledWhileCreatingAndDestroyingLeavesAConsistentFile) {
    create();
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0);
    chm_bp_status_t st;
    ASSERT_EQ(chm_bp_status(&st), 0);
    const std::uint32_t free0 = st.common_free;
    unsigned seed = 12345;
    int held_registry = 0, held_arena = 0;
    for (int round = 0; round < 100; ++round) {
        Pipe ready;
        const pid_t c = spawn([&] {
            if (chm_bp_join(path_.c_str(), 1, nullptr)) return 1;
            ready.put('r');
            char name[16];
            for (unsigned i = 0;; ++i) {
                std::snprintf(name, sizeof name, "churn%u", i % 6);
                void* q = nullptr;
                if (chm_shm_create(name, 64 + (i % 5) * 700, i % 3 ? CHM_SHM_COMMON : 1, &q) == 0) (void)chm_shm_detach(q);
                std::snprintf(name, sizeof name, "churn%u", (i + 3) % 6);
                (void)chm_shm_destroy(name);
            }
        });
        ASSERT_EQ(ready.get(), 'r');
        seed = seed * 1103515245u + 12345u;
        sleep_us(100 + (seed >> 16) % 3000);
        kill(c, SIGKILL);
        // Did it die holding a lock? (Read before our monitor recovers it.)
        const bp::Attachment& a = *bp::current();
        const std::uint32_t rt = a.hdr()->registry_lock.token.load();
        if (rt && bp::token_slot(rt) == 1 && !bp::token_recovery(rt)) ++held_registry;
        for (std::uint32_t k = 0; k <= a.slots(); ++k) {
            const std::uint32_t t = (k == a.slots() ? a.common_arena() : a.local_arena(k))->lock.token.load();
            if (t && bp::token_slot(t) == 1 && !bp::token_recovery(t)) ++held_arena;
        }
        EXPECT_EQ(reap(c), -SIGKILL);
        ASSERT_TRUE(wait_slot_state(1, CHM_BP_DEAD)) << "round " << round;
        const std::string problems = check_now();
        ASSERT_EQ(problems, "") << "round " << round;
    }
    std::printf("killed 100 times mid-churn: holding the registry lock %d times, an arena lock %d times\n",
                held_registry, held_arena);
    EXPECT_GT(held_registry, 0);
    // Whatever survived is consistent and can be cleaned up completely.
    char name[16];
    for (int i = 0; i < 6; ++i) {
        std::snprintf(name, sizeof name, "churn%d", i);
        (void)chm_shm_destroy(name);
    }
    ASSERT_EQ(chm_bp_status(&st), 0);
    EXPECT_EQ(st.objects, 0u);
    EXPECT_EQ(st.common_free, free0);
}

TEST_F(IpcRecovery, DeadSlotsAttachmentsAreDroppedAndItsLastHoldFreed) {
    create();
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0);
    chm_bp_status_t st;
    ASSERT_EQ(chm_bp_status(&st), 0);
    const std::uint32_t free0 = st.common_free;
    void* p = nullptr;
    ASSERT_EQ(chm_shm_create("shared", 4000, CHM_SHM_COMMON, &p), 0);
    Pipe ready;
    const pid_t c = spawn([&] {
        if (chm_bp_join(path_.c_str(), 1, nullptr)) return 1;
        void* q = nullptr;
        if (chm_shm_attach("shared", &q, nullptr)) return 2;
        ready.put('r');
        pause();
        return 3;
    });
    ASSERT_EQ(ready.get(), 'r');
    ASSERT_EQ(chm_shm_destroy("shared"), 0);
    ASSERT_EQ(chm_shm_detach(p), 0);
    ASSERT_EQ(chm_bp_status(&st), 0);
    EXPECT_LT(st.common_free, free0);  // the child still holds it
    kill9(c);
    ASSERT_TRUE(wait_slot_state(1, CHM_BP_DEAD));
    ASSERT_EQ(chm_bp_status(&st), 0);
    EXPECT_EQ(st.common_free, free0);
    EXPECT_EQ(check_now(), "");
}

std::atomic<int> g_calls{0};
std::atomic<std::uint32_t> g_dead_slot{99}, g_dead_gen{0};

void on_dead(const bp::View& v, std::uint32_t entry, std::uint32_t slot, std::uint32_t gen, std::uint32_t rt) {
    // The object's lock, held by the dead RTPU, passes to the recovery.
    auto* l = v.at<bp::Lock>(v.entry(entry)->offset.load());
    if (bp::lock_acquire(v, l, rt, 1000, 1'000'000'000) == -EOWNERDEAD) bp::lock_release(l);
    g_dead_slot = slot;
    g_dead_gen = gen;
    ++g_calls;
}

TEST_F(IpcRecovery, KindCallbackRunsWithTheDeadSlot) {
    constexpr std::uint32_t kTestKind = 30;
    ASSERT_EQ(bp::register_recovery(kTestKind, on_dead), 0);
    EXPECT_EQ(bp::register_recovery(0, on_dead), -EINVAL);
    create();
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0);
    Pipe ready;
    const pid_t c = spawn([&] {
        if (chm_bp_join(path_.c_str(), 6, nullptr)) return 1;
        const bp::Attachment& a = *bp::current();
        if (bp::registry_lock(a, a.token)) return 2;
        bp::EntryInfo info{};
        if (bp::registry_create_locked(a, a.token, kTestKind, "obj", 64, bp::kWhereCommon, a.slot, &info)) return 3;
        bp::registry_unlock(a);
        if (bp::lock_acquire(a, a.at<bp::Lock>(info.offset), a.token, 1000, 1000000) != 0) return 4;
        ready.put('r');
        pause();
        return 5;
    });
    ASSERT_EQ(ready.get(), 'r');
    kill9(c);
    ASSERT_TRUE(wait_slot_state(6, CHM_BP_DEAD));
    EXPECT_EQ(g_calls.load(), 1);
    EXPECT_EQ(g_dead_slot.load(), 6u);
    EXPECT_EQ(g_dead_gen.load(), 1u);
    bp::EntryInfo info{};
    ASSERT_EQ(bp::registry_lookup(*bp::current(), "obj", kTestKind, &info), 0);  // the object stays
    EXPECT_EQ(bp::current()->at<bp::Lock>(info.offset)->token.load(), 0u);
    EXPECT_EQ(check_now(), "");
    bp::register_recovery(kTestKind, nullptr);
}

TEST_F(IpcRecovery, BpcheckNamesADeadHolderAndACorruptEntry) {
    create();
    Pipe ready;
    const pid_t c = spawn([&] {
        if (chm_bp_join(path_.c_str(), 2, nullptr)) return 1;
        void* q = nullptr;
        if (chm_shm_create("seg", 128, CHM_SHM_COMMON, &q)) return 2;
        const bp::Attachment& a = *bp::current();
        if (bp::registry_lock(a, a.token)) return 3;
        ready.put('r');
        pause();
        return 4;
    });
    ASSERT_EQ(ready.get(), 'r');
    kill9(c);  // nobody attached: nobody recovers it yet
    std::string out;
    EXPECT_EQ(bpcheck(path_, &out), 1) << out;
    EXPECT_NE(out.find("header.registry_lock: held by a dead owner"), std::string::npos) << out;
    EXPECT_NE(out.find("rtpu[2]: RUNNING but process"), std::string::npos) << out;

    // Joining recovers it; then break an entry by hand.
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0);
    ASSERT_TRUE(wait_slot_state(2, CHM_BP_DEAD));
    EXPECT_EQ(bpcheck(path_, &out), 0) << out;
    bp::EntryInfo info{};
    ASSERT_EQ(bp::registry_lookup(*bp::current(), "seg", bp::kKindShm, &info), 0);
    bp::current()->entry(info.index)->offset.store(bp::current()->size + 64);
    EXPECT_EQ(bpcheck(path_, &out), 1) << out;
    EXPECT_NE(out.find("registry[" + std::to_string(info.index) + "].offset"), std::string::npos) << out;
    bp::current()->entry(info.index)->offset.store(info.offset);
    bp::current()->common_arena()->used_bytes.fetch_add(16);
    EXPECT_EQ(bpcheck(path_, &out), 1) << out;
    EXPECT_NE(out.find("common.used_bytes"), std::string::npos) << out;
    bp::current()->common_arena()->used_bytes.fetch_sub(16);
}

TEST_F(IpcRecovery, MonitorThreadBlocksEverySignal) {
    create();
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0);
    // Find our threads other than this one: the monitor is among them.
    const std::string self = std::to_string(gettid());
    int checked = 0;
    if (DIR* d = opendir("/proc/self/task")) {
        while (dirent* e = readdir(d)) {
            if (e->d_name[0] == '.' || self == e->d_name) continue;
            std::ifstream f(std::string("/proc/self/task/") + e->d_name + "/status");
            std::string line;
            while (std::getline(f, line)) {
                if (line.rfind("SigBlk:", 0) != 0) continue;
                const unsigned long long mask = std::stoull(line.substr(7), nullptr, 16);
                const int sig = port::timer_signal();
                EXPECT_TRUE(mask & (1ull << (sig - 1))) << line;
                EXPECT_TRUE(mask & (1ull << (SIGTERM - 1))) << line;
                ++checked;
            }
        }
        closedir(d);
    }
    EXPECT_GE(checked, 1);
}

}  // namespace
}  // namespace chm::test
