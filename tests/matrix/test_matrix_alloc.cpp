// "Nothing allocates": this program defines the whole malloc family itself
// (counting, then serving from the Chimera heap as libchimera's own
// interposer does) and replaces operator new, so every allocation in the
// process -- Eigen's, the C library's, ours -- passes through a counter.
// Every matrix call, success and each refusal, at small and large sizes
// (where Eigen's default product would use its blocked kernel), must leave
// the counter unchanged; so must a failure raised as an error signal in a
// task with global handling on, on a 16 KiB stack (no large stack buffers
// either). The counter is shown to see allocations.
#include <gtest/gtest.h>

#include <Eigen/Core>

#include <atomic>
#include <cerrno>
#include <cstdlib>
#include <limits>
#include <new>
#include <unistd.h>
#include <vector>

#include "chimera/chimera.h"
#include "chimera/mem.h"

namespace {
std::atomic<long> g_allocs{0};
}

extern "C" {
void* malloc(size_t n) noexcept {
    g_allocs.fetch_add(1, std::memory_order_relaxed);
    return chm_malloc(n);
}
void free(void* p) noexcept { chm_free(p); }
void* calloc(size_t n, size_t size) noexcept {
    g_allocs.fetch_add(1, std::memory_order_relaxed);
    return chm_calloc(n, size);
}
void* realloc(void* p, size_t n) noexcept {
    g_allocs.fetch_add(1, std::memory_order_relaxed);
    return chm_realloc(p, n);
}
void* reallocarray(void* p, size_t n, size_t size) noexcept {
    size_t bytes = 0;
    if (__builtin_mul_overflow(n, size, &bytes)) {
        errno = ENOMEM;
        return nullptr;
    }
    return realloc(p, bytes);
}
void* memalign(size_t align, size_t n) noexcept {
    g_allocs.fetch_add(1, std::memory_order_relaxed);
    return chm_memalign(align, n);
}
void* aligned_alloc(size_t align, size_t n) noexcept { return memalign(align, n); }
int posix_memalign(void** out, size_t align, size_t n) noexcept {
    if (align < sizeof(void*) || (align & (align - 1)) != 0) return EINVAL;
    void* p = memalign(align, n);
    if (!p) return ENOMEM;
    *out = p;
    return 0;
}
void* valloc(size_t n) noexcept { return memalign(size_t(sysconf(_SC_PAGESIZE)), n); }
void* pvalloc(size_t n) noexcept {
    const size_t page = size_t(sysconf(_SC_PAGESIZE));
    return memalign(page, (n + page - 1) / page * page);
}
size_t malloc_usable_size(void* p) noexcept { return chm_malloc_usable_size(p); }
}

void* operator new(size_t n) {
    if (void* p = malloc(n ? n : 1)) return p;
    std::abort();  // built without exceptions in mind: out of memory ends the test
}
void* operator new[](size_t n) { return operator new(n); }
void operator delete(void* p) noexcept { free(p); }
void operator delete[](void* p) noexcept { free(p); }
void operator delete(void* p, size_t) noexcept { free(p); }
void operator delete[](void* p, size_t) noexcept { free(p); }

namespace {

// Storage for every call, made before counting starts.
struct Arena {
    static constexpr uint32_t kBig = 48;
    std::vector<double> a, b, c, out, work;
    Arena()
        : a(kBig * kBig), b(kBig * kBig), c(kBig * kBig), out(kBig * kBig),
          work(CHM_MAT_WORK(kBig)) {
        for (size_t i = 0; i < a.size(); ++i) {
            a[i] = double((i * 7919) % 101) - 50;
            b[i] = double((i * 104729) % 97) - 48;
        }
        for (uint32_t i = 0; i < kBig; ++i) a[i * kBig + i] += 4000;  // regular
    }
};

// Every function of chimera/matrix.h, successes at n = 1, 3, 6 and 48 and a
// strided block, then one call per refusal code. Returns how many failed
// unexpectedly (the counter is the real verdict).
int exercise(Arena& m) {
    int bad = 0;
    auto ok = [&](int rc) { bad += rc != 0; };
    auto fails = [&](int rc) { bad += rc >= 0; };
    for (uint32_t n : {1u, 3u, 6u, Arena::kBig}) {
        chm_mat_t a, b, c, o, v3, blk;
        ok(chm_mat_view(&a, m.a.data(), n, n));
        ok(chm_mat_view_stride(&b, m.b.data(), n, n, Arena::kBig));
        ok(chm_mat_view(&c, m.c.data(), n, n));
        ok(chm_mat_view(&o, m.out.data(), n, n));
        ok(chm_mat_vector(&v3, m.c.data() + n * n, 3));
        ok(chm_mat_block(&blk, &b, 0, 0, n, n));
        ok(chm_mat_copy(&a, &c));
        ok(chm_mat_subcopy(&a, 0, 0, n, n, &c, 0, 0));
        ok(chm_mat_fill(&o, 1.5));
        ok(chm_mat_identity(&o));
        ok(chm_mat_add(&a, &blk, &o));
        ok(chm_mat_sub(&o, &a, &o));
        ok(chm_mat_scale(&o, 0.25, &o));
        ok(chm_mat_mul(&a, &blk, &o));
        ok(chm_mat_transpose(&a, &o));
        ok(chm_mat_transpose(&o, &o));
        double r = 0;
        chm_mat_t col, row;
        ok(chm_mat_block(&col, &a, 0, 0, n, 1));
        ok(chm_mat_block(&row, &b, 0, 0, 1, n));
        ok(chm_mat_dot(&col, &row, &r));
        chm_mat_t x3, y3;
        ok(chm_mat_vector(&x3, m.out.data() + n * n, 3));
        ok(chm_mat_vector(&y3, m.out.data() + n * n + 3, 3));
        ok(chm_mat_cross(&x3, &y3, &v3));
        for (int k = 0; k < 4; ++k) ok(chm_mat_norm(&a, chm_mat_norm_kind(k), &r));
        ok(chm_mat_det(&a, &r, m.work.data(), m.work.size()));
        ok(chm_mat_copy(&blk, &c));
        chm_mat_t rhs;
        ok(chm_mat_block(&rhs, &c, 0, 0, n, 1));
        ok(chm_mat_solve(&a, &rhs, &rhs, m.work.data(), m.work.size()));
        ok(chm_mat_inverse(&a, &o, m.work.data(), m.work.size()));
        ok(chm_mat_inverse(&o, &o, m.work.data(), m.work.size()));
    }
    // Every refusal, formatting its message.
    chm_mat_t s, t, u, sing;
    ok(chm_mat_view(&s, m.a.data(), 3, 4));
    ok(chm_mat_view(&t, m.b.data(), 3, 4));
    ok(chm_mat_view(&u, m.out.data(), 3, 3));
    fails(chm_mat_view(&u, nullptr, 1, 1));
    fails(chm_mat_block(&u, &s, 2, 2, 2, 2));
    fails(chm_mat_mul(&s, &t, &u));
    ok(chm_mat_view(&u, m.a.data() + 1, 3, 4));
    fails(chm_mat_add(&s, &t, &u));
    fails(chm_mat_det(&s, nullptr, m.work.data(), 12));
    ok(chm_mat_view(&sing, m.out.data(), 2, 2));
    ok(chm_mat_fill(&sing, 1));
    fails(chm_mat_inverse(&sing, &sing, m.work.data(), 1));
    fails(chm_mat_inverse(&sing, &sing, m.work.data(), m.work.size()));
    m.out[0] = std::numeric_limits<double>::quiet_NaN();
    fails(chm_mat_inverse(&sing, &sing, m.work.data(), m.work.size()));
    fails(chm_mat_norm(&s, chm_mat_norm_kind(9), nullptr));
    bad += chm_mat_last_error()[0] == '\0';
    return bad;
}

TEST(MatrixAlloc, TheCounterSeesAllocations) {
    const long before = g_allocs.load();
    std::vector<double>* v = new std::vector<double>(100);
    EXPECT_GE(g_allocs.load() - before, 2);
    delete v;
    // Eigen's own path: a dynamic matrix and its default (blocked) product.
    const long mid = g_allocs.load();
    {
        Eigen::MatrixXd x = Eigen::MatrixXd::Ones(64, 64);
        Eigen::MatrixXd y = x * x;
        EXPECT_EQ(y(0, 0), 64);
    }
    EXPECT_GE(g_allocs.load() - mid, 2);
}

TEST(MatrixAlloc, NoCallAllocates) {
    Arena m;
    (void)chm_mat_err_module();
    exercise(m);  // once, so first-use costs (none expected) are not hidden
    const long before = g_allocs.load();
    const int bad = exercise(m);
    const long after = g_allocs.load();
    EXPECT_EQ(bad, 0);
    EXPECT_EQ(after - before, 0) << "allocations during the matrix calls";
}

Arena* g_arena = nullptr;
long g_task_allocs = -1;
int g_task_bad = -1;
int g_raised = 0;
chm_err_action_t count_and_continue(const chm_err_info_t*, void*) {
    ++g_raised;
    return CHM_ERR_CONTINUE;
}
void raising_task(void*) {
    (void)chm_err_global(1);
    (void)chm_err_on_module(chm_mat_err_module(), count_and_continue, nullptr);
    const long before = g_allocs.load();
    g_task_bad = exercise(*g_arena);
    g_task_allocs = g_allocs.load() - before;
}

TEST(MatrixAlloc, NoCallAllocatesInATaskThatRaisesItsFailures) {
    Arena m;
    g_arena = &m;
    chm_kernel_config_t cfg;
    chm_kernel_config_init(&cfg);
    cfg.virtual_clock = 1;
    ASSERT_EQ(chm_kernel_init(&cfg), 0);
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = "ctl";
    // A small stack: Eigen's blocked product would put its 36 KiB of
    // packed 48x48 operands there, and the task would die of it.
    a.stack_size = 16 * 1024;
    chm_tid_t id;
    ASSERT_EQ(chm_task_spawn(&id, raising_task, nullptr, &a), 0);
    ASSERT_EQ(chm_kernel_run(), 0);
    chm_kernel_fini();
    EXPECT_EQ(g_task_bad, 0) << "-1: the task did not finish";
    EXPECT_EQ(g_raised, 9) << "one signal per refusal";
    EXPECT_EQ(g_task_allocs, 0);
}

}  // namespace
