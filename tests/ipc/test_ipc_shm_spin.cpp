// Global shared memory and spin-locks between real processes.
#include <atomic>
#include <cstdint>

#include "chimera/chimera.h"
#include "chimera/shm.h"
#include "chimera/spin.h"
#include "ipc/backplane/backplane.hpp"
#include "ipc_fixture.hpp"

namespace chm::test {
namespace {

using IpcShm = IpcTest;
using IpcSpin = IpcTest;

TEST_F(IpcShm, CommonSegmentCrossesProcesses) {
    create();
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), "host", nullptr), 0);
    void* p = nullptr;
    ASSERT_EQ(chm_shm_create("buf", 4096, CHM_SHM_COMMON, &p), 0) << chm_bp_last_error();
    ASSERT_EQ(reinterpret_cast<std::uintptr_t>(p) % 16, 0u);
    auto* words = static_cast<std::uint32_t*>(p);
    for (int i = 0; i < 512; ++i) EXPECT_EQ(words[i], 0u);  // zero-filled
    for (int i = 0; i < 512; ++i) words[i] = 0xC0DE0000u + i;
    const pid_t c = spawn([&] {
        if (chm_bp_join(path_.c_str(), 1, nullptr)) return 1;
        void* q = nullptr;
        size_t size = 0;
        if (chm_shm_attach("buf", &q, &size) || size != 4096) return 2;
        auto* w = static_cast<std::uint32_t*>(q);
        for (int i = 0; i < 512; ++i)
            if (w[i] != 0xC0DE0000u + i) return 3;
        for (int i = 512; i < 1024; ++i) w[i] = 0xBEEF0000u + i;
        if (chm_shm_detach(q)) return 4;
        return chm_bp_leave();
    });
    ASSERT_EQ(reap(c), 0);
    for (int i = 512; i < 1024; ++i) ASSERT_EQ(words[i], 0xBEEF0000u + i);
}

TEST_F(IpcShm, LocalWindowSegmentIsInThatRtpusWindow) {
    create();
    Pipe ready, done;
    const pid_t c = spawn([&] {
        if (chm_bp_join(path_.c_str(), 2, nullptr)) return 1;
        void* q = nullptr;
        if (chm_shm_create("win2", 1000, 2, &q)) return 2;
        std::memcpy(q, "hello from RTPU 2", 18);
        ready.put('r');
        if (done.get(20000) != 'd') return 3;
        if (std::strcmp(static_cast<char*>(q) + 100, "hello back") != 0) return 4;
        return chm_bp_leave();
    });
    ASSERT_EQ(ready.get(), 'r');
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0);
    void* p = nullptr;
    size_t size = 0;
    ASSERT_EQ(chm_shm_attach("win2", &p, &size), 0) << chm_bp_last_error();
    EXPECT_EQ(size, 1000u);
    EXPECT_STREQ(static_cast<char*>(p), "hello from RTPU 2");
    const bp::Attachment* a = bp::current();
    const std::uint32_t off = a->off_of(p);
    const std::uint32_t lo = a->hdr()->regions[bp::kRegionLocals].offset + 2 * a->hdr()->geo.local_window_size;
    EXPECT_GE(off, lo);
    EXPECT_LT(off, lo + a->hdr()->geo.local_window_size);
    std::strcpy(static_cast<char*>(p) + 100, "hello back");
    done.put('d');
    EXPECT_EQ(reap(c), 0);
    // The segment outlives its creator's departure; we still hold it.
    EXPECT_STREQ(static_cast<char*>(p), "hello from RTPU 2");
}

TEST_F(IpcShm, ErrorsAndDestroyFreesAfterLastDetach) {
    create();
    void* p = nullptr;
    EXPECT_EQ(chm_shm_create("x", 64, CHM_SHM_COMMON, &p), -ENOTCONN);
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0);
    chm_bp_status_t st;
    ASSERT_EQ(chm_bp_status(&st), 0);
    const std::uint32_t free0 = st.common_free;
    EXPECT_EQ(chm_shm_create("x", 0, CHM_SHM_COMMON, &p), -EINVAL);
    EXPECT_EQ(chm_shm_create("", 64, CHM_SHM_COMMON, &p), -EINVAL);
    EXPECT_EQ(chm_shm_create("a-name-that-is-much-longer-than-31", 64, CHM_SHM_COMMON, &p), -ENAMETOOLONG);
    EXPECT_EQ(chm_shm_create("x", 64, 8, &p), -ECHRNG);
    EXPECT_EQ(chm_shm_create("x", 64, -2, &p), -ECHRNG);
    EXPECT_EQ(chm_shm_create("x", 1 << 20, CHM_SHM_COMMON, &p), -ENOMEM);
    EXPECT_NE(std::strstr(chm_bp_last_error(), "common memory"), nullptr) << chm_bp_last_error();
    EXPECT_EQ(chm_shm_attach("nope", &p, nullptr), -ENOENT);
    EXPECT_EQ(chm_shm_destroy("nope"), -ENOENT);
    ASSERT_EQ(chm_shm_create("x", 64, CHM_SHM_COMMON, &p), 0);
    void* q = nullptr;
    EXPECT_EQ(chm_shm_create("x", 64, 3, &q), -EEXIST);
    EXPECT_EQ(chm_shm_detach(static_cast<char*>(p) + 16), -EINVAL);
    int x = 0;
    EXPECT_EQ(chm_shm_detach(&x), -EINVAL);

    // Destroy with an attachment left: name gone, memory kept until detach.
    void* p2 = nullptr;
    ASSERT_EQ(chm_shm_attach("x", &p2, nullptr), 0);
    EXPECT_EQ(p2, p);
    ASSERT_EQ(chm_shm_destroy("x"), 0);
    EXPECT_EQ(chm_shm_attach("x", &q, nullptr), -ENOENT);
    ASSERT_EQ(chm_shm_create("x", 64, CHM_SHM_COMMON, &q), 0);  // the name is free again
    EXPECT_NE(q, p);
    ASSERT_EQ(chm_shm_detach(p), 0);
    ASSERT_EQ(chm_bp_status(&st), 0);
    EXPECT_LT(st.common_free, free0 - 80);  // still held: one more detach to go
    ASSERT_EQ(chm_shm_detach(p2), 0);
    ASSERT_EQ(chm_shm_destroy("x"), 0);
    ASSERT_EQ(chm_shm_detach(q), 0);
    ASSERT_EQ(chm_bp_status(&st), 0);
    EXPECT_EQ(st.common_free, free0);
    EXPECT_EQ(st.objects, 0u);

    // A full registry says so.
    char name[16];
    for (int i = 0; i < 32; ++i) {
        std::snprintf(name, sizeof name, "seg%d", i);
        ASSERT_EQ(chm_shm_create(name, 16, i % 8, &p), 0) << name << ": " << chm_bp_last_error();
    }
    EXPECT_EQ(chm_shm_create("one-too-many", 16, CHM_SHM_COMMON, &p), -ENOSPC);
}

struct Shared {
    chm_spin_t lock;
    std::uint64_t counter;  // plain: only the lock protects it
};

TEST_F(IpcSpin, MutualExclusionAcrossProcessesLosesNoUpdate) {
    constexpr int kProcs = 3;
    constexpr int kPerProc = 20000;
    create();
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0);
    void* p = nullptr;
    ASSERT_EQ(chm_shm_create("counter", sizeof(Shared), CHM_SHM_COMMON, &p), 0);
    auto* s = static_cast<Shared*>(p);
    ASSERT_EQ(chm_spin_init(&s->lock), 0);
    Pipe go;
    std::vector<pid_t> kids;
    for (int k = 1; k <= kProcs; ++k) {
        kids.push_back(spawn([&, k] {
            if (chm_bp_join(path_.c_str(), k, nullptr)) return 1;
            void* q = nullptr;
            if (chm_shm_attach("counter", &q, nullptr)) return 2;
            auto* sh = static_cast<Shared*>(q);
            if (go.get() < 0) return 3;
            for (int i = 0; i < kPerProc; ++i) {
                if (chm_spin_lock(&sh->lock, 2000, 10'000'000'000ull) != 0) return 4;
                sh->counter = sh->counter + 1;
                if (chm_spin_unlock(&sh->lock) != 0) return 5;
            }
            return chm_bp_leave();
        }));
    }
    for (int k = 0; k < kProcs; ++k) go.put('g');
    for (pid_t k : kids) EXPECT_EQ(reap(k, 60000), 0);
    EXPECT_EQ(s->counter, std::uint64_t(kProcs) * kPerProc);
    EXPECT_EQ(s->lock.word, 0u);
}

// m68k's ABI aligns a uint32_t to 2 bytes: a lock after a char in a struct
// (or on the stack) was refused as misaligned (-EINVAL) there until the
// type carried its alignment (chimera/spin.h). Fails under qemu-m68k
// without it; natively the layout was right already.
TEST(IpcSpinLayout, ALockAnywhereInAStructIsAValidLock) {
    struct AfterChar {
        char tag;
        chm_spin_t lock;
    };
    AfterChar locks[3] = {};
    for (auto& e : locks) {
        EXPECT_EQ(reinterpret_cast<std::uintptr_t>(&e.lock) % 4, 0u);
        EXPECT_EQ(chm_spin_init(&e.lock), 0);
    }
}

TEST_F(IpcSpin, TimeoutIsBoundedAndUnlockChecksTheOwner) {
    create();
    chm_spin_t local;
    EXPECT_EQ(chm_spin_init(&local), 0);
    EXPECT_EQ(chm_spin_lock(&local, 0, 0), -ENOTCONN);
    EXPECT_EQ(chm_spin_init(nullptr), -EINVAL);
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0);
    void* p = nullptr;
    ASSERT_EQ(chm_shm_create("lock", sizeof(chm_spin_t), CHM_SHM_COMMON, &p), 0);
    auto* l = static_cast<chm_spin_t*>(p);
    ASSERT_EQ(chm_spin_init(l), 0);
    Pipe ready, done;
    const pid_t c = spawn([&] {
        if (chm_bp_join(path_.c_str(), 1, nullptr)) return 1;
        void* q = nullptr;
        if (chm_shm_attach("lock", &q, nullptr)) return 2;
        if (chm_spin_lock(static_cast<chm_spin_t*>(q), 1000, 1'000'000'000) != 0) return 3;
        ready.put('r');
        if (done.get(20000) != 'd') return 4;
        if (chm_spin_unlock(static_cast<chm_spin_t*>(q))) return 5;
        return chm_bp_leave();
    });
    ASSERT_EQ(ready.get(), 'r');
    EXPECT_EQ(chm_spin_try_lock(l), -EAGAIN);
    EXPECT_EQ(chm_spin_trylock(l), -EBUSY) << "the name before API 1.0 keeps its status";
    EXPECT_EQ(chm_spin_unlock(l), -EPERM);  // not ours
    EXPECT_EQ(chm_spin_lock(l, 100000, CHM_NO_WAIT), -EAGAIN);
    const std::uint64_t t0 = now_ns();
    EXPECT_EQ(chm_spin_lock(l, 100000, 50'000'000), -ETIMEDOUT);
    const std::uint64_t waited = now_ns() - t0;
    std::printf("spin-lock timeout of 50 ms returned after %.2f ms\n", waited / 1e6);
    EXPECT_GE(waited, 50'000'000u);
    EXPECT_LT(waited, 2'000'000'000u);
    done.put('d');
    EXPECT_EQ(chm_spin_lock(l, 100000, 10'000'000'000ull), 0);
    EXPECT_EQ(chm_spin_unlock(l), 0);
    EXPECT_EQ(reap(c), 0);
}

TEST_F(IpcSpin, HolderKilledNextLockerGetsOwnerDead) {
    create();
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0);
    void* p = nullptr;
    ASSERT_EQ(chm_shm_create("lock", sizeof(Shared), CHM_SHM_COMMON, &p), 0);
    auto* s = static_cast<Shared*>(p);
    ASSERT_EQ(chm_spin_init(&s->lock), 0);
    for (int round = 0; round < 5; ++round) {
        Pipe ready;
        const pid_t c = spawn([&] {
            if (chm_bp_join(path_.c_str(), 4, nullptr)) return 1;
            void* q = nullptr;
            if (chm_shm_attach("lock", &q, nullptr)) return 2;
            auto* sh = static_cast<Shared*>(q);
            if (chm_spin_lock(&sh->lock, 1000, 5'000'000'000ull) != 0) return 3;
            sh->lock.dirty = 1;  // "in the middle of a change"
            ready.put('r');
            pause();
            return 4;
        });
        ASSERT_EQ(ready.get(), 'r');
        kill9(c);
        EXPECT_EQ(chm_spin_lock(&s->lock, 10000, 5'000'000'000ull), -EOWNERDEAD) << "round " << round;
        EXPECT_EQ(s->lock.dirty, 1u);  // the repairer sees what was left
        s->lock.dirty = 0;
        EXPECT_EQ(chm_spin_unlock(&s->lock), 0);
        EXPECT_EQ(chm_spin_lock(&s->lock, 10000, 1'000'000'000), 0);
        EXPECT_EQ(chm_spin_unlock(&s->lock), 0);
    }
}

// Inside a Chimera task a long spin gives the CPU to the RTPU's other
// tasks: a more urgent task waiting for the lock lets the holder run and
// release it (busy-spinning would starve the holder forever).
std::atomic<int> g_waiter_result{1};
chm_spin_t* g_lock = nullptr;

void waiter(void*) { g_waiter_result = chm_spin_lock(g_lock, 200'000, 5'000'000'000ull); (void)chm_spin_unlock(g_lock); }

void holder(void*) {
    if (chm_spin_lock(g_lock, 1000, 1'000'000'000) != 0) return;
    chm_task_attr_t attr;
    chm_task_attr_init(&attr);
    attr.priority = 10;  // more urgent than us: it runs at once and spins
    attr.name = "waiter";
    chm_tid_t tid;
    (void)chm_task_spawn(&tid, waiter, nullptr, &attr);
    (void)chm_spin_unlock(g_lock);  // reached only if the waiter gave the CPU away
}

TEST_F(IpcSpin, SpinningTaskYieldsToItsRtpusOtherTasks) {
    create();
    ASSERT_EQ(chm_bp_join(path_.c_str(), 1, nullptr), 0);
    void* p = nullptr;
    ASSERT_EQ(chm_shm_create("lock", sizeof(chm_spin_t), CHM_SHM_COMMON, &p), 0);
    g_lock = static_cast<chm_spin_t*>(p);
    ASSERT_EQ(chm_spin_init(g_lock), 0);
    chm_kernel_config_t cfg;
    chm_kernel_config_init(&cfg);
    cfg.policy = CHM_SCHED_FIXED;
    ASSERT_EQ(chm_kernel_init(&cfg), 0);
    chm_task_attr_t attr;
    chm_task_attr_init(&attr);
    attr.name = "holder";
    chm_tid_t tid;
    ASSERT_EQ(chm_task_spawn(&tid, holder, nullptr, &attr), 0);
    EXPECT_EQ(chm_kernel_run(), 0);
    chm_kernel_fini();
    EXPECT_EQ(g_waiter_result.load(), 0);
    EXPECT_EQ(g_lock->word, 0u);
}

}  // namespace
}  // namespace chm::test
