// Named stop points (stop_point.hpp): the slow path, taken only before the
// environment was read or while a point is armed.
#include "ipc/backplane/stop_point.hpp"

#include <csignal>
#include <cstdlib>
#include <cstring>

namespace chm::stop {

std::atomic<int> g_state{0};

namespace {

char g_name[128];               // the armed point's name (written before g_state says 2)
std::atomic<bool> g_fired{false};  // stops once per process: a retry loop passes the point again

void read_env() {
    const char* e = std::getenv("CHIMERA_STOP_AT");
    // A name longer than the buffer cannot be one of ours: off.
    if (!e || !*e || std::strlen(e) >= sizeof g_name) {
        g_state.store(1, std::memory_order_relaxed);
        return;
    }
    std::strcpy(g_name, e);
    g_state.store(2, std::memory_order_release);
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
    if (s != 2 || std::strcmp(name, g_name) != 0) return;
    if (g_fired.exchange(true)) return;
    ::raise(SIGSTOP);  // every thread of the process stops; SIGCONT goes on from here
}

void reload() {
    g_fired.store(false);
    g_state.store(0, std::memory_order_release);
}

}  // namespace chm::stop
