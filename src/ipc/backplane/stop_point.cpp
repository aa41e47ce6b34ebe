// Named stop points (stop_point.hpp): the slow path, taken only before the
// environment was read or while a point is armed.
#include "ipc/backplane/stop_point.hpp"

#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "chimera/err.h"
#include "chimera/task.h"
#include "kernel/task/holds.hpp"
#include "port.hpp"

namespace chm::stop {

std::atomic<int> g_state{0};

namespace {

enum class Action { Stop, Kill, Abort, Fault, Destroy, AbortCycle };

struct Named {
    const char* name;
    Action action;
};
constexpr Named kActions[] = {{"stop", Action::Stop},       {"kill", Action::Kill},
                              {"abort", Action::Abort},     {"fault", Action::Fault},
                              {"destroy", Action::Destroy}, {"abort_cycle", Action::AbortCycle}};

// The armed points' names: the variable's text with each ',' made a '\0'
// (written before g_state says 2); one action for them all.
constexpr int kMaxPoints = 8;
char g_names[128];
const char* g_name[kMaxPoints];
int g_points = 0;
Action g_action = Action::Stop;
std::atomic<unsigned> g_fired{0};  // a bit per point: each acts once per process (a retry loop passes it again)

void off() { g_state.store(1, std::memory_order_relaxed); }

void read_env() {
    const char* f = std::getenv("CHIMERA_FAULT_AT");
    const char* e = f && *f ? f : std::getenv("CHIMERA_STOP_AT");
    // A name longer than the buffer cannot be one of ours: off.
    if (!e || !*e || std::strlen(e) >= sizeof g_names) return off();
    std::strcpy(g_names, e);
    g_action = Action::Stop;
    if (e == f) {
        char* colon = std::strrchr(g_names, ':');
        bool known = false;
        if (colon)
            for (const Named& a : kActions)
                if (std::strcmp(colon + 1, a.name) == 0) {
                    g_action = a.action;
                    known = true;
                }
        if (!known) {
            std::fprintf(stderr,
                         "chimera: CHIMERA_FAULT_AT=%s: expected <point>:<action>, the action one of "
                         "stop, kill, abort, fault, destroy, abort_cycle; no fault injected\n", e);
            return off();
        }
        *colon = '\0';
    }
    g_points = 0;
    for (char* p = g_names; g_points < kMaxPoints;) {
        g_name[g_points++] = p;
        p = std::strchr(p, ',');
        if (!p) break;
        *p++ = '\0';
    }
    g_state.store(2, std::memory_order_release);
}

bool in_task() { return port::on_kernel_thread() && chm_task_self() != CHM_TID_NONE; }

// A processor exception in the task (a store to an unmapped address, read
// from a volatile so the compiler cannot see it), as a bad user buffer in
// the call would raise; the kernel's fault handler takes it.
volatile std::uintptr_t g_bad_address = 16;
__attribute__((no_sanitize("address", "undefined"), noinline)) void fault_now() {
    *reinterpret_cast<volatile int*>(g_bad_address) = 1;
}

}  // namespace

void hit(const char* name) {
    int s = g_state.load(std::memory_order_acquire);
    if (s == 0) {
        // One thread reads the environment (3: being read). Another that
        // passes a point meanwhile goes on without stopping rather than
        // wait: it may be a task of higher priority than the reader.
        int unread = 0;
        if (g_state.compare_exchange_strong(unread, 3, std::memory_order_acquire)) read_env();
        s = g_state.load(std::memory_order_acquire);
    }
    if (s != 2) return;
    int point = 0;
    while (point < g_points && std::strcmp(name, g_name[point]) != 0) ++point;
    if (point == g_points) return;
    // The task actions wait for a task to pass the point (a host thread
    // of the same process passes it untouched).
    const bool task_action = g_action != Action::Stop && g_action != Action::Kill;
    if (task_action && !in_task()) return;
    if (g_fired.fetch_or(1u << point) & (1u << point)) return;
    switch (g_action) {
    case Action::Stop: ::raise(SIGSTOP); break;  // every thread stops; SIGCONT goes on from here
    case Action::Kill: ::raise(SIGKILL); break;
    case Action::Abort: (void)chm_err_invoke(CHM_ERR_KERNEL, EFAULT); break;  // the default handler aborts
    case Action::Fault: fault_now(); break;
    case Action::Destroy: (void)chm_task_destroy(chm_task_self()); break;
    case Action::AbortCycle: kernel::abort_cycle_current(); break;
    }
}

void reload() {
    g_fired.store(0);
    g_state.store(0, std::memory_order_release);
}

}  // namespace chm::stop
