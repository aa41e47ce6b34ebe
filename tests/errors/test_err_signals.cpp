// Error signals in one RTPU on the virtual clock: the default line and
// abort of only the failing task, handler precedence (scope, code, module,
// task), nested scopes, each outcome (continue, abort, return to a mark),
// global handling of calls on and off, deadline misses without a handler,
// owner-died release of semaphores, and many errors without a leak.
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <fcntl.h>
#include <string>
#include <vector>

#include "chimera/mem.h"
#include "err_test_util.hpp"

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

class ErrSignals : public ::testing::Test {
protected:
    void SetUp() override {
        chm_kernel_config_t cfg;
        chm_kernel_config_init(&cfg);
        cfg.virtual_clock = 1;
        cfg.quantum_ns = 0;
        ASSERT_EQ(chm_kernel_init(&cfg), 0);
    }
    void TearDown() override { chm_kernel_fini(); }
};

const chm_err_code_t kValveCodes[] = {{7, "valve stuck"}, {8, "valve leaking"}};
int valve_module() {
    static int id = chm_err_module_register("valve", kValveCodes, 2);
    return id;
}

std::vector<std::string> g_log;
volatile bool g_after = false;
int g_raise_line = 0;

void raiser(void*) {
    g_raise_line = __LINE__ + 1;
    CHM_ERR_INVOKE(valve_module(), 7);
    g_after = true;  // never reached: the default handler aborts the task
}

int g_sibling_cycles = 0;
void sibling(void*) {
    for (int i = 0; i < 20; ++i) {
        ++g_sibling_cycles;
        chm_time_consume(1 * kMs);
        chm_task_wait_period();
    }
}

TEST_F(ErrSignals, ModulesRegisterOnceWithTheirMessages) {
    const int m = valve_module();
    ASSERT_GT(m, CHM_ERR_UNIX);
    EXPECT_EQ(chm_err_module_register("valve", kValveCodes, 2), -EEXIST);
    EXPECT_EQ(chm_err_module_register("", kValveCodes, 2), -EINVAL);
    const chm_err_code_t bad[] = {{0, "zero"}};
    EXPECT_EQ(chm_err_module_register("bad", bad, 1), -EINVAL);
    EXPECT_EQ(chm_err_module_find("valve"), m);
    EXPECT_EQ(chm_err_module_find("kernel"), CHM_ERR_KERNEL);
    EXPECT_EQ(chm_err_module_find("nope"), -ENOENT);
    EXPECT_STREQ(chm_err_message(m, 8), "valve leaking");
    EXPECT_STREQ(chm_err_message(CHM_ERR_UNIX, ENOENT), strerror(ENOENT));
    EXPECT_STREQ(chm_err_message(CHM_ERR_CPU, CHM_ECPU_STACK), "stack overflow");
    EXPECT_EQ(chm_err_invoke(999, 1), -EINVAL);
}

TEST_F(ErrSignals, DefaultHandlerPrintsOneLineAndAbortsOnlyThatTask) {
    g_after = false;
    g_sibling_cycles = 0;
    chm_err_rtpu_set(3);
    const chm_tid_t id = spawn_task(raiser, nullptr, "raiser", 5);
    spawn_task(sibling, nullptr, "sibling", 1, 2 * kMs);
    StderrCapture cap;
    ASSERT_EQ(chm_kernel_run(), 0);
    const std::string err = cap.text();
    chm_err_rtpu_set(-1);
    EXPECT_FALSE(g_after);
    EXPECT_EQ(g_sibling_cycles, 20) << "the sibling keeps its period";
    const std::string want = "chimera: RTPU 3 task raiser (id " + std::to_string(id) +
                             "): valve error 7 (valve stuck) at " + __FILE__ + ":" +
                             std::to_string(g_raise_line) + "\n";
    EXPECT_EQ(err, want);
}

// ---- precedence
chm_err_action_t rec(const chm_err_info_t* info, void* arg) {
    g_log.push_back(std::string(static_cast<const char*>(arg)) + ":" + std::to_string(info->code));
    return CHM_ERR_CONTINUE;
}
chm_err_action_t rec_pass(const chm_err_info_t* info, void* arg) {
    g_log.push_back(std::string(static_cast<const char*>(arg)) + ":" + std::to_string(info->code));
    return CHM_ERR_PASS;
}

void precedence_body(void*) {
    const int m = valve_module();
    EXPECT_EQ(chm_err_on_task(rec, (void*)"task"), 0);
    EXPECT_EQ(chm_err_on_module(m, rec, (void*)"module"), 0);
    EXPECT_EQ(chm_err_on_code(m, 7, rec, (void*)"code"), 0);
    chm_err_scope_t outer, inner;
    EXPECT_EQ(chm_err_scope_push(&outer, rec, (void*)"outer"), 0);
    EXPECT_EQ(chm_err_scope_push(&inner, rec_pass, (void*)"inner"), 0);
    EXPECT_EQ(chm_err_invoke(m, 7), 0);  // inner passes, outer takes it
    EXPECT_EQ(chm_err_scope_pop(&outer), -EINVAL) << "not the innermost";
    EXPECT_EQ(chm_err_scope_pop(&inner), 0);
    EXPECT_EQ(chm_err_scope_pop(&outer), 0);
    EXPECT_EQ(chm_err_invoke(m, 7), 0);  // per code
    EXPECT_EQ(chm_err_invoke(m, 8), 0);  // per module
    EXPECT_EQ(chm_err_invoke(CHM_ERR_KERNEL, CHM_EK_HEAP), 0);  // per task
    EXPECT_EQ(chm_err_on_code(m, 7, nullptr, nullptr), 0);
    EXPECT_EQ(chm_err_invoke(m, 7), 0);  // falls to the module handler now
    EXPECT_EQ(chm_err_on_module(m, nullptr, nullptr), 0);
    EXPECT_EQ(chm_err_invoke(m, 7), 0);  // and to the task's
}

TEST_F(ErrSignals, ScopeThenCodeThenModuleThenTask) {
    g_log.clear();
    spawn_task(precedence_body, nullptr, "prec");
    ASSERT_EQ(chm_kernel_run(), 0);
    const std::vector<std::string> want = {"inner:7", "outer:7", "code:7", "module:8",
                                           "task:1002", "module:7", "task:7"};
    EXPECT_EQ(g_log, want);
}

// Every task has its own set: a handler installed by one task is not seen
// by another.
volatile bool g_other_aborted = true;
void installs(void*) {
    (void)chm_err_on_module(valve_module(), rec, (void*)"mine");
    chm_task_yield();
}
void relies_on_someone_elses(void*) {
    chm_task_yield();
    StderrCapture cap;
    chm_err_invoke(valve_module(), 8);
    g_other_aborted = false;
}
TEST_F(ErrSignals, EveryTaskHasItsOwnSet) {
    g_log.clear();
    g_other_aborted = true;
    spawn_task(installs, nullptr, "installs", 2);
    spawn_task(relies_on_someone_elses, nullptr, "other", 2);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_TRUE(g_log.empty());
    EXPECT_TRUE(g_other_aborted) << "the default handler ran for the other task";
}

// ---- outcomes
chm_err_action_t to_mark(const chm_err_info_t*, void*) { return CHM_ERR_TO_MARK; }
chm_err_action_t abort_it(const chm_err_info_t* info, void*) {
    g_log.push_back("abort:" + std::to_string(info->code));
    return CHM_ERR_ABORT;
}

int g_mark_value = -1;
int g_mark_passes = 0;
void deep(int n) {
    if (n == 0) chm_err_invoke(valve_module(), 8);
    else deep(n - 1);
    g_after = true;
}
void mark_body(void*) {
    chm_err_scope_t s;
    (void)chm_err_on_task(to_mark, nullptr);
    chm_err_mark_t m;
    volatile int passes = 0;
    const int v = chm_err_mark(&m);
    passes = passes + 1;
    if (v == 0) {
        (void)chm_err_scope_push(&s, rec_pass, (void*)"scope");  // popped by the return
        deep(10);
    }
    g_mark_value = v;
    g_mark_passes = passes;
    EXPECT_EQ(chm_err_scope_pop(&s), -EINVAL) << "the return to the mark popped it";
    EXPECT_EQ(chm_err_unmark(&m), 0);
    // No mark left: TO_MARK aborts the task with the default line.
    chm_err_invoke(valve_module(), 7);
    g_log.push_back("after");
}

TEST_F(ErrSignals, ReturnToMarkUnwindsAndPopsScopes) {
    g_log.clear();
    g_after = false;
    spawn_task(mark_body, nullptr, "marker");
    StderrCapture cap;
    ASSERT_EQ(chm_kernel_run(), 0);
    const std::string err = cap.text();
    EXPECT_EQ(g_mark_value, 8);
    EXPECT_EQ(g_mark_passes, 2);
    EXPECT_FALSE(g_after);
    EXPECT_EQ(g_log, std::vector<std::string>{"scope:8"});
    EXPECT_NE(err.find("valve error 7 (valve stuck): no mark set to return to"), std::string::npos) << err;
}

void continue_then_abort(void*) {
    (void)chm_err_on_code(valve_module(), 7, rec, (void*)"cont");
    (void)chm_err_on_code(valve_module(), 8, abort_it, nullptr);
    EXPECT_EQ(chm_err_invoke(valve_module(), 7), 0);
    g_log.push_back("continued");
    chm_err_invoke(valve_module(), 8);
    g_log.push_back("not reached");
}
TEST_F(ErrSignals, ContinueReturnsAbortEndsTheTaskSilently) {
    g_log.clear();
    spawn_task(continue_then_abort, nullptr, "ca");
    StderrCapture cap;
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(cap.text(), "") << "a handler that aborts speaks for itself";
    EXPECT_EQ(g_log, (std::vector<std::string>{"cont:7", "continued", "abort:8"}));
}

// An error raised inside a handler goes to the default handler.
chm_err_action_t raises_again(const chm_err_info_t*, void*) {
    chm_err_invoke(valve_module(), 8);
    g_log.push_back("not reached");
    return CHM_ERR_CONTINUE;
}
void nested_raise(void*) {
    (void)chm_err_on_code(valve_module(), 7, raises_again, nullptr);
    chm_err_invoke(valve_module(), 7);
    g_log.push_back("not reached either");
}
TEST_F(ErrSignals, ErrorInsideAHandlerGoesToTheDefaultHandler) {
    g_log.clear();
    spawn_task(nested_raise, nullptr, "nested");
    StderrCapture cap;
    ASSERT_EQ(chm_kernel_run(), 0);
    const std::string err = cap.text();
    EXPECT_TRUE(g_log.empty());
    EXPECT_EQ(count_lines(err, "chimera: RTPU"), 1);
    EXPECT_NE(err.find("valve error 8"), std::string::npos) << err;
}

// ---- global handling of calls
std::string g_seen;
int g_ret = 0, g_errno = 0;
chm_err_action_t note(const chm_err_info_t* info, void*) {
    g_seen = std::string(info->module_name) + "/" + std::to_string(info->code) + "/" +
             (info->call ? info->call : "-") + "/" + (info->detail ? info->detail : "-");
    return CHM_ERR_CONTINUE;
}
void open_off(void*) {
    errno = 0;
    g_ret = chm_open("/nonexistent/chimera-errors", O_RDONLY);
    g_errno = errno;
}
void open_on_handled(void*) {
    EXPECT_EQ(chm_err_global(1), 0);
    EXPECT_EQ(chm_err_global_get(), 1);
    (void)chm_err_on_module(CHM_ERR_UNIX, note, nullptr);
    g_ret = chm_open("/nonexistent/chimera-errors", O_RDONLY);
    g_errno = errno;
}
void open_on_default(void*) {
    (void)chm_err_global(1);
    const int fd = chm_open("/nonexistent/chimera-errors", O_RDONLY);  // the paper's line
    g_ret = fd;
    g_log.push_back("not reached");
}

TEST_F(ErrSignals, GlobalOffOpenReturnsMinusOneAndErrno) {
    g_seen.clear();
    spawn_task(open_off, nullptr, "off");
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_ret, -1);
    EXPECT_EQ(g_errno, ENOENT);
    EXPECT_EQ(g_seen, "");
}

TEST_F(ErrSignals, GlobalOnOpenRaisesAndContinueKeepsErrno) {
    g_seen.clear();
    spawn_task(open_on_handled, nullptr, "on");
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_seen, "unix/" + std::to_string(ENOENT) + "/open//nonexistent/chimera-errors");
    EXPECT_EQ(g_ret, -1);
    EXPECT_EQ(g_errno, ENOENT);
}

TEST_F(ErrSignals, GlobalOnOpenWithoutHandlerAbortsWithTheLine) {
    g_log.clear();
    g_ret = 0;
    const chm_tid_t id = spawn_task(open_on_default, nullptr, "ctrl");
    StderrCapture cap;
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(cap.text(), "chimera: RTPU 1 task ctrl (id " + std::to_string(id) + "): unix error " +
                              std::to_string(ENOENT) + " (" + strerror(ENOENT) +
                              ") in open(\"/nonexistent/chimera-errors\")\n");
    EXPECT_TRUE(g_log.empty());
}

chm_sem_t g_bad_sem;  // never initialised
void kernel_calls_on(void*) {
    (void)chm_err_global(1);
    (void)chm_err_on_module(CHM_ERR_KERNEL, note, nullptr);
    g_ret = chm_sem_p(&g_bad_sem);
    g_log.push_back(g_seen);
    g_seen.clear();
    g_log.push_back(std::to_string(chm_task_suspend(12345)));
    g_log.push_back(g_seen);
    g_seen.clear();
    chm_sem_t s;
    (void)chm_sem_init(&s, CHM_SEM_BINARY, 0, 0);
    g_log.push_back(std::to_string(chm_sem_p_timed(&s, 1000)));  // an outcome: not raised
    g_log.push_back(g_seen);
    (void)chm_err_global(0);
    g_log.push_back(std::to_string(chm_task_resume(12345)));
    g_log.push_back(g_seen);
}
TEST_F(ErrSignals, GlobalHandlingRoutesTheKernelsOwnCalls) {
    g_log.clear();
    g_seen.clear();
    spawn_task(kernel_calls_on, nullptr, "kcalls");
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_ret, -EINVAL);
    const std::vector<std::string> want = {
        "kernel/" + std::to_string(EINVAL) + "/chm_sem_p/-", std::to_string(-ESRCH),
        "kernel/" + std::to_string(ESRCH) + "/chm_task_suspend/-", std::to_string(-ETIMEDOUT), "",
        std::to_string(-ESRCH), ""};
    EXPECT_EQ(g_log, want);
}

// ---- deadline misses
int g_overrun_cycles = 0, g_handled_cycles = 0;
void overruns(void*) {
    for (;;) {
        ++g_overrun_cycles;
        chm_time_consume(g_overrun_cycles == 3 ? 15 * kMs : 1 * kMs);
        chm_task_wait_period();
        if (g_overrun_cycles >= 10) return;
    }
}
void overruns_handled(void*) {
    for (int i = 0; i < 10; ++i) {
        ++g_handled_cycles;
        chm_time_consume(i == 3 ? 15 * kMs : 1 * kMs);
        chm_task_wait_period();
    }
}
chm_deadline_action own_handler(const chm_deadline_info_t*, void*) { return CHM_DL_CONTINUE; }

TEST_F(ErrSignals, DeadlineMissWithoutHandlerIsAKernelErrorSignal) {
    g_overrun_cycles = g_handled_cycles = 0;
    const chm_tid_t id = spawn_task(overruns, nullptr, "late", 1, 10 * kMs);
    spawn_task(overruns_handled, nullptr, "handled", 2, 10 * kMs, own_handler);
    StderrCapture cap;
    ASSERT_EQ(chm_kernel_run(), 0);
    const std::string err = cap.text();
    EXPECT_EQ(g_overrun_cycles, 10) << "the default handler lets the late cycle run on";
    EXPECT_EQ(g_handled_cycles, 10) << "a task with its own handler is unchanged";
    // Cycle 2 overruns; cycle 3, released late, misses too.
    EXPECT_EQ(count_lines(err, "chimera: RTPU"), 2) << err;
    const std::string head = "chimera: RTPU 1 task late (id " + std::to_string(id) +
                             "): kernel error 1001 (deadline missed): ";
    EXPECT_EQ(err.find(head + "miss 1, cycle 2, "), 0u) << err;
    EXPECT_NE(err.find("\n" + head + "miss 2, cycle 3, "), std::string::npos) << err;
}

chm_err_action_t abort_on_miss(const chm_err_info_t* info, void*) {
    g_log.push_back("miss:" + std::to_string(info->code));
    return CHM_ERR_ABORT;
}
void overruns_strict(void*) {
    (void)chm_err_on_code(CHM_ERR_KERNEL, CHM_EK_DEADLINE, abort_on_miss, nullptr);
    overruns(nullptr);
}
TEST_F(ErrSignals, DeadlineMissHandlerMayAbortTheTask) {
    g_overrun_cycles = 0;
    g_log.clear();
    spawn_task(overruns_strict, nullptr, "strict", 1, 10 * kMs);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_overrun_cycles, 3) << "aborted in its late cycle";
    EXPECT_EQ(g_log, std::vector<std::string>{"miss:1001"});
}

// ---- owner-died semantics
chm_sem_t g_lock;
std::vector<int> g_p_results;
void holder_dies(void*) {
    ASSERT_EQ(chm_sem_p(&g_lock), 0);
    chm_task_yield();  // let the waiter queue up
    (void)chm_err_on_task(abort_it, nullptr);
    chm_err_invoke(valve_module(), 7);
}
void waiter(void*) {
    g_p_results.push_back(chm_sem_p(&g_lock));  // blocks until the holder dies
    g_p_results.push_back(chm_sem_v(&g_lock));
    g_p_results.push_back(chm_sem_p(&g_lock));  // a healthy semaphore again
    (void)chm_sem_v(&g_lock);
}
void holder_dies_alone(void*) {
    (void)chm_sem_p(&g_lock);
    (void)chm_err_on_task(abort_it, nullptr);
    chm_err_invoke(valve_module(), 7);
}
void later(void*) {
    g_p_results.push_back(chm_sem_try_p(&g_lock));
    g_p_results.push_back(chm_sem_v(&g_lock));
    g_p_results.push_back(chm_sem_try_p(&g_lock));
}

TEST_F(ErrSignals, SemaphoreOfAnAbortedTaskPassesToTheWaiterAsOwnerDead) {
    g_p_results.clear();
    g_log.clear();
    ASSERT_EQ(chm_sem_init(&g_lock, CHM_SEM_BINARY, 1, CHM_SEM_INHERIT), 0);
    spawn_task(holder_dies, nullptr, "holder", 1);
    spawn_task(waiter, nullptr, "waiter", 1);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_p_results, (std::vector<int>{-EOWNERDEAD, 0, 0}));
}

TEST_F(ErrSignals, SemaphoreOfAnAbortedTaskIsFreeForTheNextTaker) {
    g_p_results.clear();
    ASSERT_EQ(chm_sem_init(&g_lock, CHM_SEM_BINARY, 1, 0), 0);
    spawn_task(holder_dies_alone, nullptr, "holder", 2);
    spawn_task(later, nullptr, "later", 1);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_p_results, (std::vector<int>{-EOWNERDEAD, 0, 0}));
    EXPECT_EQ(chm_sem_value(&g_lock), 0);
}

// ---- many errors: no leaked handler state, heap block or lock
chm_sem_t g_shared;
int g_done = 0;
void injector(void* arg) {
    const int n = int(reinterpret_cast<intptr_t>(arg));
    (void)chm_err_on_module(valve_module(), abort_it, nullptr);  // quiet aborts
    (void)chm_err_global(1);
    (void)chm_sem_p(&g_shared);
    if (n % 3 == 0) {
        chm_err_mark_t m;
        if (chm_err_mark(&m) == 0) {
            (void)chm_err_on_task(to_mark, nullptr);
            chm_err_invoke(CHM_ERR_KERNEL, CHM_EK_HEAP);
        }
        (void)chm_err_unmark(&m);
        (void)chm_sem_v(&g_shared);
        ++g_done;
        return;
    }
    chm_err_invoke(valve_module(), 7);  // aborted holding g_shared
}
void spawner(void*) {
    for (int i = 0; i < 1000; ++i) {
        spawn_task(injector, reinterpret_cast<void*>(intptr_t(i)), "inj", 1);
        chm_task_yield();
    }
}
TEST_F(ErrSignals, AThousandErrorsLeakNothing) {
    g_log.clear();
    g_done = 0;
    ASSERT_EQ(chm_sem_init(&g_shared, CHM_SEM_BINARY, 1, 0), 0);
    g_log.shrink_to_fit();
    struct chm_mem_stats before{}, after{};
    ASSERT_EQ(chm_mem_stats(&before), 0);
    spawn_task(spawner, nullptr, "spawner", 0);
    ASSERT_EQ(chm_kernel_run(), 0);
    EXPECT_EQ(g_done, 334);
    EXPECT_EQ(g_log.size(), 666u);
    g_log.clear();
    g_log.shrink_to_fit();
    ASSERT_EQ(chm_mem_stats(&after), 0);
    EXPECT_EQ(after.used_blocks, before.used_blocks) << "per-task error state freed";
    EXPECT_EQ(chm_sem_value(&g_shared), 1) << "the semaphore is free again";
    EXPECT_EQ(chm_mem_check(), 0);
}

}  // namespace
}  // namespace chm::test
