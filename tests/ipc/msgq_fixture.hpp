// Scaffolding of the message-queue tests: queue creation, the strict
// checker, bounded polling, and an RTPU child (kernel + backplane join +
// wake binding) that runs the tasks a test spawns.
#pragma once

#include <atomic>
#include <functional>
#include <string>

#include "chimera/chimera.h"
#include "chimera/msgq.h"
#include "ipc/backplane/backplane.hpp"
#include "ipc/msgq/msgq.hpp"
#include "ipc/wake/wake.hpp"
#include "ipc_fixture.hpp"
#include "rtpu_child.hpp"

namespace chm::test {

class MsgqTest : public IpcTest {
protected:
    chm_msgq_t* make_queue(const char* name, chm_msgq_order order, std::uint32_t max_msg, std::uint32_t count,
                           int where = CHM_MSGQ_COMMON) {
        chm_msgq_attr_t a;
        chm_msgq_attr_init(&a);
        a.order = order;
        a.max_msg = max_msg;
        a.max_count = count;
        chm_msgq_t* q = nullptr;
        const int r = chm_msgq_create(name, &a, where, &q);
        EXPECT_EQ(r, 0) << chm_bp_last_error();
        return r ? nullptr : q;
    }
    // The strict check of one queue: "" when consistent.
    static std::string check(chm_msgq_t* h) {
        std::string out;
        bp::Report r;
        r.emit = report_lines;
        r.ctx = &out;
        auto* q = reinterpret_cast<ipc::msgq::QueueHeader*>(h);
        ipc::msgq::check_queue(*bp::current(), q, q->total_size, "queue", r);
        return out;
    }
    static chm_msgq_info_t info(chm_msgq_t* q) {
        chm_msgq_info_t st{};
        EXPECT_EQ(chm_msgq_info(q, &st), 0);
        return st;
    }
    // Poll `cond` every 100 µs for at most timeout_ms.
    static bool wait_for(const std::function<bool()>& cond, int timeout_ms = 10000) {
        const std::uint64_t end = now_ns() + std::uint64_t(timeout_ms) * 1000000u;
        while (!cond()) {
            if (now_ns() > end) return false;
            sleep_us(100);
        }
        return true;
    }
    // In a forked child: join as RTPU n, start a kernel (fixed priorities,
    // real clock) bound to the backplane, let `setup` spawn tasks, run
    // until a task calls chm_kernel_stop(code); returns the code.
    static int run_rtpu(const std::string& path, int n, const std::function<void()>& setup) {
        return test::run_rtpu(path, n, [&] { return setup(), true; }, RtpuOptions{CHM_SCHED_FIXED, 0});
    }
    // A late cycle of a periodic task just continues (a loaded machine is
    // not what these tests are about).
    static chm_deadline_action keep_going(const chm_deadline_info_t*, void*) { return CHM_DL_CONTINUE; }
    static void spawn_task(void (*fn)(void*), void* arg, const char* name, int prio, std::uint64_t period) {
        if (test::spawn_task(fn, arg, name, prio, period, keep_going) == CHM_TID_NONE) _exit(104);
    }
};

}  // namespace chm::test
