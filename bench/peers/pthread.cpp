// Peers: the kernel thread as a task. pthread_create+join is what
// task_create/destroy and task_spawn_run_exit are judged against (glibc caches
// thread stacks, so this is its best case); pthread_setschedparam stands
// beside task_set_priority.
#include <pthread.h>
#include <sched.h>

#include <cstdint>
#include <cstring>

#include "../harness.hpp"

namespace chm::bench {
namespace {

void* empty_thread(void*) { return nullptr; }

void pthread_create_join(Session& s) {
    Session::pin(s.cpu(0));  // the new thread inherits the pinning
    s.time_ops("peer_pthread_create_join", "pinned " + s.cpu_name(0) + ", default attributes",
               [&](std::uint64_t n) {
                   for (std::uint64_t i = 0; i < n; ++i) {
                       pthread_t t;
                       if (int e = pthread_create(&t, nullptr, empty_thread, nullptr))
                           fail_errno("pthread_create", e);
                       pthread_join(t, nullptr);
                   }
               });
}
CHM_BENCH_MEASUREMENT(pthread_create_join, "peer_pthread_create_join");

void setschedparam(Session& s) {
    Session::pin(s.cpu(0));
    int policy;
    sched_param sp;
    check(pthread_getschedparam(pthread_self(), &policy, &sp) == 0, "pthread_getschedparam");
    // Re-applying the current parameters still takes the full system call
    // path (permission checks, runqueue lock); changing SCHED_OTHER's
    // priority is not possible, and raising a real-time one needs privilege.
    s.time_ops("peer_setschedparam",
               "pinned " + s.cpu_name(0) + ", re-applies the thread's own policy " +
                   std::to_string(policy) + " priority " + std::to_string(sp.sched_priority),
               [&](std::uint64_t n) {
                   for (std::uint64_t i = 0; i < n; ++i)
                       if (int e = pthread_setschedparam(pthread_self(), policy, &sp))
                           fail_errno("pthread_setschedparam", e);
               });
}
CHM_BENCH_MEASUREMENT(setschedparam, "peer_setschedparam");

}  // namespace
}  // namespace chm::bench
