// Choosing the scheduler at start-up, calling it, and falling back to MUF
// when a user scheduler misbehaves (returns a task that is not ready).
#include <cerrno>
#include <cstring>
#include <initializer_list>
#include <unistd.h>

#include "kernel.hpp"

namespace chm::kernel {

namespace {

bool g_trusted = true;  // built-in tables skip the validity check
int g_fallbacks = 0;
char g_reason[160] = "";

void say(const char* a, const char* b, const char* c) {
    // write(2): this can run inside the timer signal handler.
    char line[256];
    std::size_t n = 0;
    for (const char* part : {a, b, c})
        for (; *part && n < sizeof line - 2; ++part) line[n++] = *part;
    line[n++] = '\n';
    ssize_t w = write(2, line, n);
    (void)w;
}

bool valid_ready_locked(chm_sched_task_t* h) {
    return tcb_view_valid(h) && tcb_of(h)->in_ready;
}

void append(char* dst, std::size_t cap, const char* src) {
    std::size_t n = std::strlen(dst);
    while (*src && n + 1 < cap) dst[n++] = *src++;
    dst[n] = 0;
}

void fall_back_to_muf_locked(const char* why) {
    const char* name = g_k.ops->name ? g_k.ops->name : "(unnamed)";
    g_reason[0] = 0;  // no snprintf: this may run in the signal handler
    append(g_reason, sizeof g_reason, "user scheduler '");
    append(g_reason, sizeof g_reason, name);
    append(g_reason, sizeof g_reason, "' ");
    append(g_reason, sizeof g_reason, why);
    ++g_fallbacks;
    say("chimera: ", g_reason, "; falling back to MUF");
    // Rebuild MUF's view of every task from scratch.
    g_k.ops = &chm_sched_muf_ops;
    g_k.ops_self = nullptr;
    g_k.policy = CHM_SCHED_MUF;
    g_k.builtin = true;
    g_trusted = true;
    g_k.rq.clear();
    g_k.muf = MufSet{};
    for (std::uint32_t i = 0; i < g_k.tcb_hw; ++i) {
        Tcb* t = &g_k.tcbs[i];
        if (t->used && t->state != TaskState::Ended) g_k.ops->admit(nullptr, &t->s);
    }
    const std::uint64_t now = now_locked();
    for (std::uint32_t i = 0; i < g_k.tcb_hw; ++i) {
        Tcb* t = &g_k.tcbs[i];
        if (t->used && t->in_ready) g_k.ops->enqueue(nullptr, &t->s, now);
    }
}

}  // namespace

int sched_select(chm_sched_policy policy, const chm_sched_ops_t* user, void* user_arg) {
    const chm_sched_ops_t* ops = nullptr;
    g_trusted = true;
    switch (policy) {
    case CHM_SCHED_MUF: ops = &chm_sched_muf_ops; break;
    case CHM_SCHED_RM: ops = &chm_sched_rm_ops; break;
    case CHM_SCHED_EDF: ops = &chm_sched_edf_ops; break;
    case CHM_SCHED_MLF: ops = &chm_sched_mlf_ops; break;
    case CHM_SCHED_FIXED: ops = &chm_sched_fixed_ops; break;
    case CHM_SCHED_USER:
        if (!user || !user->admit || !user->retire || !user->enqueue || !user->dequeue ||
            !user->pick || !user->before)
            return -EINVAL;  // a table with missing operations
        ops = user;
        g_trusted = false;
        break;
    default: return -EINVAL;
    }
    g_k.ops = ops;
    g_k.ops_self = policy == CHM_SCHED_USER ? user_arg : nullptr;
    g_k.policy = policy;
    g_k.builtin = policy != CHM_SCHED_USER;
    g_fallbacks = 0;
    g_reason[0] = 0;
    return 0;
}

Tcb* sched_pick_user_locked(std::uint64_t now) {
    if (g_k.ops->update) g_k.ops->update(g_k.ops_self, now);
    chm_sched_task_t* h = g_k.ops->pick(g_k.ops_self, now);
    if (!h) return nullptr;
    if (!g_trusted && !valid_ready_locked(h)) {
        fall_back_to_muf_locked("returned a task that is not ready");
        return sched_pick_locked(now);
    }
    return tcb_of(h);
}

}  // namespace chm::kernel

extern "C" int chm_sched_fallbacks(void) { return chm::kernel::g_fallbacks; }
extern "C" const char* chm_sched_fallback_reason(void) { return chm::kernel::g_reason; }
extern "C" enum chm_sched_policy chm_kernel_policy(void) { return chm::kernel::g_k.policy; }
