// Global error handling covers IPC (issue 15 item 5): with it on, a bad
// remote-semaphore, message-queue, shared-memory and spin-lock call raises
// an error signal of module "ipc" (a handler sees the module, the code and
// the call; the default handler aborts only the task); outcomes (a try on
// an empty semaphore or queue, a held spin lock) raise nothing; with it
// off, and on a thread that is not a task, the same calls just return
// their status.
#include <atomic>
#include <cerrno>
#include <cstring>
#include <string>
#include <vector>

#include "chimera/chimera.h"
#include "chimera/err.h"
#include "chimera/msgq.h"
#include "chimera/rsem.h"
#include "chimera/shm.h"
#include "chimera/spin.h"
#include "ipc_fixture.hpp"

namespace chm::test {
namespace {

struct Seen {
    int module;
    int code;
    std::string call;
};
std::vector<Seen> g_seen;
std::vector<int> g_status;  // what each call returned
bool g_global = true;
bool g_after_abort = false;
int g_sibling_ran = 0;
chm_spin_t* g_spin = nullptr;  // in a shared segment: free, held by no one

chm_err_action_t record(const chm_err_info_t* info, void*) {
    g_seen.push_back(Seen{info->module, info->code, info->call ? info->call : ""});
    return CHM_ERR_CONTINUE;  // the call then returns its status
}

// One bad call of each subsystem, then outcomes that must never raise.
void bad_calls() {
    chm_rsem_t* s = nullptr;
    chm_msgq_t* q = nullptr;
    void* p = nullptr;
    char buf[8];
    g_status.push_back(chm_rsem_open("no-such-sem", &s));                  // -ENOENT
    g_status.push_back(chm_rsem_v(nullptr));                               // -EINVAL
    g_status.push_back(chm_msgq_open("no-such-queue", &q));                // -ENOENT
    g_status.push_back(chm_msgq_send(nullptr, 1, 0, "x", 1));              // -EINVAL
    g_status.push_back(chm_shm_attach("no-such-segment", &p, nullptr));    // -ENOENT
    g_status.push_back(chm_shm_create("seg", 0, CHM_SHM_COMMON, &p));      // -EINVAL
    g_status.push_back(chm_spin_unlock(g_spin));                           // -EPERM
    g_status.push_back(chm_spin_init(nullptr));                            // -EINVAL
    // Outcomes.
    chm_rsem_t* empty = nullptr;
    chm_msgq_t* none = nullptr;
    if (chm_rsem_open("empty", &empty) == 0) g_status.push_back(chm_rsem_try_p(empty));  // -EAGAIN
    if (chm_msgq_open("q", &none) == 0)
        g_status.push_back(chm_msgq_try_receive(none, buf, sizeof buf, nullptr));  // -EAGAIN
}

void controller(void*) {
    (void)chm_err_global(g_global ? 1 : 0);
    (void)chm_err_on_module(chm_ipc_err_module(), record, nullptr);
    bad_calls();
}

void unhandled(void*) {
    (void)chm_err_global(1);
    chm_rsem_t* s = nullptr;
    (void)chm_rsem_open("no-such-sem", &s);  // the default handler aborts the task here
    g_after_abort = true;
}

void sibling(void*) {
    for (int i = 0; i < 5; ++i) {
        ++g_sibling_ran;
        chm_task_yield();
    }
}

class IpcErrors : public IpcTest {
protected:
    // Attach as RTPU 1 with an empty semaphore, an empty queue and a free
    // spin lock in common memory, then run the given tasks.
    void run(std::initializer_list<void (*)(void*)> tasks) {
        create();
        ASSERT_EQ(chm_bp_join(path_.c_str(), 1, nullptr), 0) << chm_bp_last_error();
        chm_rsem_t* s = nullptr;
        ASSERT_EQ(chm_rsem_create("empty", CHM_SEM_COUNTING, 0, CHM_SHM_COMMON, &s), 0);
        chm_msgq_attr_t qa;
        chm_msgq_attr_init(&qa);
        chm_msgq_t* q = nullptr;
        ASSERT_EQ(chm_msgq_create("q", &qa, CHM_MSGQ_COMMON, &q), 0) << chm_bp_last_error();
        void* p = nullptr;
        ASSERT_EQ(chm_shm_create("spin", sizeof(chm_spin_t), CHM_SHM_COMMON, &p), 0);
        g_spin = static_cast<chm_spin_t*>(p);
        ASSERT_EQ(chm_spin_init(g_spin), 0);
        chm_kernel_config_t cfg;
        chm_kernel_config_init(&cfg);
        cfg.policy = CHM_SCHED_FIXED;
        ASSERT_EQ(chm_kernel_init(&cfg), 0);
        for (auto fn : tasks) {
            chm_task_attr_t a;
            chm_task_attr_init(&a);
            chm_tid_t tid;
            ASSERT_EQ(chm_task_spawn(&tid, fn, nullptr, &a), 0);
        }
        EXPECT_EQ(chm_kernel_run(), 0);
        chm_kernel_fini();
    }
    void SetUp() override {
        IpcTest::SetUp();
        g_seen.clear();
        g_status.clear();
        g_after_abort = false;
        g_sibling_ran = 0;
    }
};

const std::vector<int> kStatuses = {-ENOENT, -EINVAL, -ENOENT, -EINVAL, -ENOENT,
                                    -EINVAL, -EPERM,  -EINVAL, -EAGAIN, -EAGAIN};

TEST_F(IpcErrors, GlobalHandlingRaisesModuleIpcForBadCallsOnly) {
    g_global = true;
    run({controller});
    EXPECT_EQ(g_status, kStatuses);  // the handler continued: the same statuses
    const int m = chm_ipc_err_module();
    ASSERT_GT(m, 0);
    EXPECT_STREQ(chm_err_module_name(m), "ipc");
    const std::vector<std::pair<int, std::string>> want = {
        {ENOENT, "chm_rsem_open"}, {EINVAL, "chm_rsem_v"},     {ENOENT, "chm_msgq_open"},
        {EINVAL, "chm_msgq_send"}, {ENOENT, "chm_shm_attach"}, {EINVAL, "chm_shm_create"},
        {EPERM, "chm_spin_unlock"}, {EINVAL, "chm_spin_init"},
    };
    ASSERT_EQ(g_seen.size(), want.size());  // the two outcomes raised nothing
    for (size_t i = 0; i < want.size(); ++i) {
        EXPECT_EQ(g_seen[i].module, m) << i;
        EXPECT_EQ(g_seen[i].code, want[i].first) << i;
        EXPECT_EQ(g_seen[i].call, want[i].second) << i;
    }
}

TEST_F(IpcErrors, WithGlobalHandlingOffTheCallsReturnTheirStatus) {
    g_global = false;
    run({controller});
    EXPECT_EQ(g_status, kStatuses);
    EXPECT_TRUE(g_seen.empty());
}

TEST_F(IpcErrors, DefaultHandlerAbortsOnlyTheFailingTask) {
    run({unhandled, sibling});
    EXPECT_FALSE(g_after_abort);
    EXPECT_EQ(g_sibling_ran, 5);
}

TEST_F(IpcErrors, AThreadThatIsNotATaskGetsTheStatus) {
    create();
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0) << chm_bp_last_error();
    chm_rsem_t* s = nullptr;
    EXPECT_EQ(chm_rsem_open("no-such-sem", &s), -ENOENT);
    EXPECT_EQ(chm_spin_init(nullptr), -EINVAL);
}

}  // namespace
}  // namespace chm::test
