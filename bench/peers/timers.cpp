// Peers: re-arming a POSIX timer (what every tickless reschedule pays) and a
// signal to oneself with its handler (what a timer interrupt costs in user
// space: the floor under timer_resched_noswitch and tick_cpu_locked).
#include <signal.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

#include <cstdint>

#include "../harness.hpp"

namespace chm::bench {
namespace {

void timer_rearm(Session& s) {
    Session::pin(s.cpu(0));
    sigevent sev{};
    sev.sigev_notify = SIGEV_NONE;  // it never fires: we only pay the re-arm
    timer_t t;
    check(timer_create(CLOCK_MONOTONIC, &sev, &t) == 0, "timer_create");
    s.time_ops("peer_timer_settime",
               "pinned " + s.cpu_name(0) + ", CLOCK_MONOTONIC, relative one-shot ~1 s ahead",
               [&](std::uint64_t n) {
                   itimerspec its{};
                   its.it_value.tv_sec = 1;
                   for (std::uint64_t i = 0; i < n; ++i) {
                       its.it_value.tv_nsec = long(i & 1023);  // a new expiry each time
                       if (timer_settime(t, 0, &its, nullptr) != 0) {
                           timer_delete(t);
                           fail_errno("timer_settime");
                       }
                   }
               });
    timer_delete(t);
}
CHM_BENCH_MEASUREMENT(timer_rearm, "peer_timer_settime");

volatile sig_atomic_t g_handled = 0;
void on_usr1(int) { g_handled = g_handled + 1; }

void signal_self(Session& s) {
    Session::pin(s.cpu(0));
    struct sigaction sa{}, old{};
    sa.sa_handler = on_usr1;
    sigemptyset(&sa.sa_mask);
    sa.sa_flags = SA_RESTART;
    check(sigaction(SIGUSR1, &sa, &old) == 0, "sigaction");
    sigset_t set, old_mask;
    sigemptyset(&set);
    sigaddset(&set, SIGUSR1);
    pthread_sigmask(SIG_UNBLOCK, &set, &old_mask);
    const pid_t pid = getpid(), tid = gettid();
    try {
        // The handler runs before tgkill returns (on the way out of the
        // kernel), so one iteration is the whole round trip.
        s.time_ops("peer_signal_self", "pinned " + s.cpu_name(0) + ", tgkill(SIGUSR1) to this thread",
                   [&](std::uint64_t n) {
                       const sig_atomic_t before = g_handled;
                       for (std::uint64_t i = 0; i < n; ++i) syscall(SYS_tgkill, pid, tid, SIGUSR1);
                       if (g_handled == before) throw std::runtime_error("the handler never ran");
                   });
    } catch (...) {
        sigaction(SIGUSR1, &old, nullptr);
        pthread_sigmask(SIG_SETMASK, &old_mask, nullptr);
        throw;
    }
    sigaction(SIGUSR1, &old, nullptr);
    pthread_sigmask(SIG_SETMASK, &old_mask, nullptr);
}
CHM_BENCH_MEASUREMENT(signal_self, "peer_signal_self");

}  // namespace
}  // namespace chm::bench
