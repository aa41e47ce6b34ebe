// The torn-read hunt: a writer task on one RTPU writes a 64-double vector
// as fast as it can, every element of write n equal to n; reader tasks on
// two other RTPUs copy it in (chm_svar_set_read) millions of times. A read
// that mixes two writes shows as unequal elements; a read older than the
// previous one, as a value going back. Neither may ever happen. The
// writer's task is preempted by its RTPU's ticker mid-write now and then,
// so readers meet a writer stopped in the middle of a copy too.
#include <gtest/gtest.h>

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "chimera/chimera.h"
#include "../ipc/ipc_fixture.hpp"
#include "../ipc/rtpu_child.hpp"

using namespace chm::test;

namespace {

constexpr int kElems = 64;
constexpr std::uint64_t kMs = 1'000'000;

// Shared by the processes through a shared-memory segment.
struct Board {
    std::atomic<std::uint32_t> stop;
    std::atomic<std::uint32_t> readers_done;
    std::atomic<std::uint32_t> reads[2], torn[2], backwards[2], distinct[2], writes;  // 32-bit: m68k has no 64-bit atomics
};

Board* board() {
    void* p = nullptr;
    return chm_shm_attach("board", &p, nullptr) == 0 ? static_cast<Board*>(p) : nullptr;
}

// Reads per reader: millions natively; under qemu a read costs ~50x more.
std::uint64_t reads_wanted() {
    const char* e = std::getenv("CHM_TORN_READS");
    return e && *e ? std::strtoull(e, nullptr, 10) : 3'000'000ull;
}

void writer(void*) {
    Board* b = board();
    const char* outs[] = {"v"};
    chm_svar_set_t* s = nullptr;
    if (!b) return chm_kernel_stop(80);
    if (const int r = chm_svar_set_create("writer", nullptr, 0, outs, 1, &s)) {
        std::fprintf(stderr, "writer: chm_svar_set_create: %d %s\n", r, chm_err_last());
        return chm_kernel_stop(83);
    }
    auto* v = static_cast<double*>(chm_svar_set_local(s, "v"));
    std::uint64_t n = 0;
    while (!b->stop.load(std::memory_order_relaxed)) {
        ++n;
        for (int k = 0; k < kElems; ++k) v[k] = double(n);
        (void)chm_svar_set_write(s);
    }
    b->writes.store(std::uint32_t(n));
    (void)chm_svar_set_destroy(s);
    chm_kernel_stop(0);
}

int g_reader = 0;
void reader(void*) {
    Board* b = board();
    const char* ins[] = {"v"};
    chm_svar_set_t* s = nullptr;
    if (!b) return chm_kernel_stop(81);
    if (const int r = chm_svar_set_create("reader", ins, 1, nullptr, 0, &s)) {
        std::fprintf(stderr, "reader %d: chm_svar_set_create: %d %s\n", g_reader, r, chm_err_last());
        return chm_kernel_stop(82);
    }
    const auto* v = static_cast<const double*>(chm_svar_set_local(s, "v"));
    const std::uint64_t want = reads_wanted();
    std::uint64_t reads = 0, torn = 0, backwards = 0, distinct = 0;
    double last = 0;
    // Until enough reads AND enough of them overlapped the writer's work
    // (under an emulator the writer's process may start late), bounded.
    const std::uint64_t give_up = chm_time_now() + 30'000'000'000ull;
    while ((reads < want || distinct < 1000) && !b->stop.load(std::memory_order_relaxed) &&
           (reads % 4096 || chm_time_now() < give_up)) {
        if (chm_svar_set_read(s) != 0) continue;
        ++reads;
        bool same = true;
        for (int k = 1; k < kElems; ++k) same &= v[k] == v[0];
        torn += !same;
        backwards += v[0] < last;
        distinct += v[0] != last;
        last = v[0];
    }
    b->reads[g_reader] = std::uint32_t(reads);
    b->torn[g_reader] = std::uint32_t(torn);
    b->backwards[g_reader] = std::uint32_t(backwards);
    b->distinct[g_reader] = std::uint32_t(distinct);
    if (b->readers_done.fetch_add(1) + 1 == 2) b->stop.store(1);
    (void)chm_svar_set_destroy(s);
    chm_kernel_stop(0);
}

void ticker(void*) {
    for (;;) chm_task_wait_period();
}

class SvarTorn : public IpcTest {};

TEST_F(SvarTorn, NoReadEverMixesTwoWrites) {
    chm_bp_config_t c = small_config();
    c.common_size = 1024 * 1024;
    create(c);
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0) << chm_bp_last_error();
    chm_svar_decl_t d{"v", CHM_SVAR_DOUBLE, kElems, 1, ""};
    ASSERT_EQ(chm_svar_declare(&d), 0) << chm_bp_last_error();
    void* p = nullptr;
    ASSERT_EQ(chm_shm_create("board", sizeof(Board), CHM_SHM_COMMON, &p), 0);
    Board* b = static_cast<Board*>(p);
    const std::string path = path_;
    const pid_t w = spawn([path] {
        return run_rtpu(path, 1, [] {
            return spawn_task(writer, nullptr, "writer", 1) != CHM_TID_NONE &&
                   spawn_task(ticker, nullptr, "ticker", 2, 1 * kMs) != CHM_TID_NONE;
        });
    });
    pid_t r[2];
    for (int i = 0; i < 2; ++i)
        r[i] = spawn([path, i] {
            g_reader = i;
            return run_rtpu(path, 2 + i, [] { return spawn_task(reader, nullptr, "reader", 1) != CHM_TID_NONE; });
        });
    // Bounded: the children end when both readers are done (alarm(60)
    // in spawn ends a hung one); their exit codes say whether they ran.
    for (pid_t x : r) EXPECT_EQ(reap(x, 120000), 0);
    b->stop.store(1);
    EXPECT_EQ(reap(w, 20000), 0);
    std::uint64_t reads = 0;
    for (int i = 0; i < 2; ++i) {
        std::fprintf(stderr, "reader %d: %llu reads, %llu distinct values seen, %llu torn, %llu backwards\n", i,
                     (unsigned long long)b->reads[i], (unsigned long long)b->distinct[i],
                     (unsigned long long)b->torn[i], (unsigned long long)b->backwards[i]);
        EXPECT_EQ(b->torn[i], 0u) << "reader " << i;
        EXPECT_EQ(b->backwards[i], 0u) << "reader " << i;
        EXPECT_GT(b->distinct[i], 100u) << "reader " << i << " saw the writer's values change";
        reads += b->reads[i];
    }
    std::fprintf(stderr, "writer: %llu writes\n", (unsigned long long)b->writes.load());
    EXPECT_GT(b->writes.load(), 1000u);
    EXPECT_GT(reads, 0u);
}

}  // namespace
