// An RTPU in a forked child of an ipc test: join the backplane, run a
// kernel whose doorbell is bound to the slot's table entry, let the test
// spawn its tasks, run until they end (or one calls chm_kernel_stop) and
// leave. Shared by the remote-semaphore, message-queue and wake-up tests.
#pragma once

#include <cstdint>
#include <string>

#include "chimera/chimera.h"
#include "ipc/wake/wake.hpp"

namespace chm::test {

struct RtpuOptions {
    chm_sched_policy policy = CHM_SCHED_MUF;  // the kernel's default
    std::uint64_t idle_poll_ns = 0;           // poll the doorbell before sleeping
    int virtual_clock = 0;                    // 1: virtual clock, doorbell not bound
};

// Returns the kernel's exit code, or 90..93 when a step before it failed
// (join, kernel init, doorbell binding, spawn_tasks() returned false).
template <class Spawn>
int run_rtpu(const std::string& path, int slot, Spawn spawn_tasks, RtpuOptions o = {}) {
    if (chm_bp_join(path.c_str(), slot, "rtpu") != 0) return 90;
    chm_kernel_config_t cfg;
    chm_kernel_config_init(&cfg);
    cfg.policy = o.policy;
    cfg.idle_poll_ns = o.idle_poll_ns;
    cfg.virtual_clock = o.virtual_clock;
    if (chm_kernel_init(&cfg) != 0) return 91;
    // A virtual-clock kernel has no thread peers can signal: not bound
    // (its own tasks still wake each other; other processes' grants do not).
    if (!o.virtual_clock && chm::ipc::wake_bind_kernel() != 0) return 92;
    if (!spawn_tasks()) return 93;
    const int r = chm_kernel_run();
    if (!o.virtual_clock) chm::ipc::wake_unbind_kernel();
    chm_kernel_fini();
    (void)(void)chm_bp_leave();
    return r;
}

// A task of priority `prio` (periodic when `period` > 0, with a small
// declared WCET; in MUF's critical set when `critical`); CHM_TID_NONE when
// the spawn failed.
inline chm_tid_t spawn_task(void (*fn)(void*), void* arg, const char* name, int prio, std::uint64_t period = 0,
                            chm_deadline_handler_t on_deadline = nullptr, int critical = 0) {
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = name;
    a.priority = prio;
    a.critical = critical;
    a.period_ns = period;
    a.wcet_ns = period ? 50000 : 0;
    a.on_deadline = on_deadline;
    chm_tid_t id = CHM_TID_NONE;
    return chm_task_spawn(&id, fn, arg, &a) == 0 ? id : CHM_TID_NONE;
}

}  // namespace chm::test
