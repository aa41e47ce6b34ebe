// The matrix library's failures through global error handling: module
// "matrix" raised in the calling task when its handling is on (call,
// detail, code, status as the header says), a handler that continues, one
// that returns to a mark, the default handler's line and abort of only that
// task, and nothing raised with handling off or outside a task.
#include <gtest/gtest.h>

#include <cerrno>
#include <cstdio>
#include <string>
#include <unistd.h>
#include <vector>

#include "chimera/chimera.h"
#include "chimera/err.h"
#include "chimera/matrix.h"

namespace chm::test {
namespace {

// Everything written to fd 2 while it lives.
class StderrCapture {
public:
    StderrCapture() {
        std::fflush(stderr);
        file_ = std::tmpfile();
        saved_ = dup(2);
        dup2(fileno(file_), 2);
    }
    std::string text() {
        std::fflush(stderr);
        dup2(saved_, 2);
        std::string s;
        std::rewind(file_);
        char buf[1024];
        size_t n;
        while ((n = std::fread(buf, 1, sizeof buf, file_)) > 0) s.append(buf, n);
        return s;
    }
    ~StderrCapture() {
        dup2(saved_, 2);
        close(saved_);
        std::fclose(file_);
    }

private:
    std::FILE* file_;
    int saved_;
};

std::vector<std::string> g_seen;  // "module code call: detail status" per signal
std::vector<int> g_status;        // what the calls returned
bool g_after = false;

class MatrixErrors : public ::testing::Test {
protected:
    void SetUp() override {
        chm_kernel_config_t cfg;
        chm_kernel_config_init(&cfg);
        cfg.virtual_clock = 1;
        cfg.quantum_ns = 0;
        ASSERT_EQ(chm_kernel_init(&cfg), 0);
        g_seen.clear();
        g_status.clear();
        g_after = false;
    }
    void TearDown() override { chm_kernel_fini(); }
};

chm_tid_t spawn(void (*fn)(void*), const char* name) {
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = name;
    a.priority = 1;
    chm_tid_t id = CHM_TID_NONE;
    EXPECT_EQ(chm_task_spawn(&id, fn, nullptr, &a), 0);
    return id;
}

chm_err_action_t record(const chm_err_info_t* info, void* action) {
    g_seen.push_back(std::string(info->module_name) + " " + std::to_string(info->code) + " " +
                     info->call + ": " + info->detail + " " + std::to_string(info->status));
    return chm_err_action_t(reinterpret_cast<intptr_t>(action));
}

double g_a[4] = {1, 2, 2, 4}, g_b[2] = {1, 2}, g_x[2] = {9, 9}, g_w[CHM_MAT_WORK(2)];
double g_big[12];

// Two failures with a handler that continues: each call returns its status.
void continues(void*) {
    chm_mat_t a, b, x, m34;
    (void)chm_mat_view(&a, g_a, 2, 2);
    (void)chm_mat_view(&b, g_b, 2, 1);
    (void)chm_mat_view(&x, g_x, 2, 1);
    (void)chm_mat_view(&m34, g_big, 3, 4);
    (void)chm_err_global(1);
    (void)chm_err_on_module(chm_mat_err_module(), record, reinterpret_cast<void*>(CHM_ERR_CONTINUE));
    g_status.push_back(chm_mat_mul(&m34, &m34, &m34));
    g_status.push_back(chm_mat_solve(&a, &b, &x, g_w, 6));
    g_status.push_back(chm_mat_add(&a, &a, &a));  // succeeds: nothing raised
    (void)chm_err_global(0);
    g_status.push_back(chm_mat_solve(&a, &b, &x, g_w, 6));  // off: only the status
    g_after = true;
}

TEST_F(MatrixErrors, AHandlerSeesTheCallAndTheDetailAndMayContinue) {
    spawn(continues, "ctl");
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_TRUE(g_after);
    EXPECT_EQ(g_status, (std::vector<int>{-EINVAL, -EDOM, 0, -EDOM}));
    ASSERT_EQ(g_seen.size(), 2u);
    EXPECT_EQ(g_seen[0],
              "matrix 2 chm_mat_mul: 3x4 times 3x4: inner dimensions differ " +
                  std::to_string(-EINVAL));
    EXPECT_EQ(g_seen[1].rfind("matrix 6 chm_mat_solve: 2x2 matrix singular: column 1's pivot 0", 0),
              0u)
        << g_seen[1];
    EXPECT_EQ(g_x[0], 9);  // nothing written
    EXPECT_STREQ(chm_err_message(chm_mat_err_module(), CHM_EMAT_SINGULAR),
                 "matrix singular to working precision");
    EXPECT_STREQ(chm_err_module_name(chm_mat_err_module()), "matrix");
}

int g_mark_value = -1;
void to_mark_body(void*) {
    chm_mat_t a, out;
    (void)chm_mat_view(&a, g_a, 2, 2);
    (void)chm_mat_view(&out, g_big, 2, 2);
    (void)chm_err_global(1);
    (void)chm_err_on_code(chm_mat_err_module(), CHM_EMAT_SINGULAR, record,
                    reinterpret_cast<void*>(CHM_ERR_TO_MARK));
    chm_err_mark_t m;
    const int v = chm_err_mark(&m);
    if (v == 0) {
        (void)chm_mat_inverse(&a, &out, g_w, 6);
        g_after = true;  // never reached: the handler returns to the mark
    }
    g_mark_value = v;
    (void)chm_err_unmark(&m);
}

TEST_F(MatrixErrors, AHandlerMayReturnToAMark) {
    spawn(to_mark_body, "ctl");
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_FALSE(g_after);
    EXPECT_EQ(g_mark_value, CHM_EMAT_SINGULAR);
    ASSERT_EQ(g_seen.size(), 1u);
}

void unhandled(void*) {
    chm_mat_t v3, v4;
    (void)chm_mat_vector(&v3, g_big, 3);
    (void)chm_mat_vector(&v4, g_big, 4);
    (void)chm_err_global(1);
    double d;
    (void)chm_mat_dot(&v3, &v4, &d);
    g_after = true;
}

int g_sibling_runs = 0;
void sibling(void*) {
    for (int i = 0; i < 3; ++i) {
        ++g_sibling_runs;
        chm_task_yield();
    }
}

TEST_F(MatrixErrors, TheDefaultHandlerPrintsOneLineAndAbortsOnlyThatTask) {
    g_sibling_runs = 0;
    const chm_tid_t id = spawn(unhandled, "ctl");
    spawn(sibling, "sibling");
    StderrCapture cap;
    ASSERT_EQ(chm_kernel_run(), 0);
    const std::string err = cap.text();
    EXPECT_FALSE(g_after);
    EXPECT_EQ(g_sibling_runs, 3);
    const std::string want = "task ctl (id " + std::to_string(id) +
                             "): matrix error 2 (dimension mismatch) in chm_mat_dot(\"3x1 dot "
                             "4x1: lengths 3 and 4 differ\")\n";
    EXPECT_NE(err.find(want), std::string::npos) << err;
    EXPECT_EQ(err.find('\n'), err.size() - 1) << "one line";
}

TEST(MatrixErrorsOutsideTasks, OnlyAStatusAndTheLastError) {
    double d[4] = {};
    chm_mat_t m;
    ASSERT_EQ(chm_mat_view(&m, d, 2, 2), 0);
    EXPECT_EQ(chm_mat_err_module(), chm_err_module_find("matrix"));
    StderrCapture cap;
    EXPECT_EQ(chm_mat_transpose(&m, nullptr), -EINVAL);
    EXPECT_EQ(cap.text(), "");
    EXPECT_STREQ(chm_mat_last_error(), "chm_mat_transpose: out: NULL view");
    EXPECT_EQ(chm_mat_last_code(), CHM_EMAT_ARG);
}

}  // namespace
}  // namespace chm::test
