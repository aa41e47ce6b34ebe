// Peers: uncontended semaphore and mutex operations in one thread (what a
// local P and V without blocking must beat), and a same-core hand-off between
// two kernel threads through sem_t (what a blocking P or a waking V with its
// switch is judged against).
#include <pthread.h>
#include <semaphore.h>

#include <atomic>
#include <cstdint>

#include "../harness.hpp"
#include "../proc.hpp"

namespace chm::bench {
namespace {

void sem_uncontended(Session& s) {
    Session::pin(s.cpu(0));
    const std::string where = "one thread pinned " + s.cpu_name(0);
    sem_t sem;
    check(sem_init(&sem, 0, 1) == 0, "sem_init");
    s.time_ops("peer_sem_wait_post", where, [&](std::uint64_t n) {
        for (std::uint64_t i = 0; i < n; ++i) {
            while (sem_wait(&sem) != 0) eintr_or_fail("sem_wait");
            sem_post(&sem);
        }
    });
    // The halves alone: post n times, then wait n times (never blocks).
    s.time_custom("peer_sem_post", where, [&](std::uint64_t n) {
        const std::uint64_t t0 = mono_ns();
        for (std::uint64_t i = 0; i < n; ++i) sem_post(&sem);
        const std::uint64_t t1 = mono_ns();
        for (std::uint64_t i = 0; i < n; ++i)
            while (sem_wait(&sem) != 0) eintr_or_fail("sem_wait");
        return double(t1 - t0);
    });
    s.time_custom("peer_sem_wait", where, [&](std::uint64_t n) {
        for (std::uint64_t i = 0; i < n; ++i) sem_post(&sem);
        const std::uint64_t t0 = mono_ns();
        for (std::uint64_t i = 0; i < n; ++i)
            while (sem_wait(&sem) != 0) eintr_or_fail("sem_wait");
        return double(mono_ns() - t0);
    });
    sem_destroy(&sem);
}
CHM_BENCH_MEASUREMENT(sem_uncontended, "peer_sem_wait_post", "peer_sem_post", "peer_sem_wait");

void mutex_uncontended(Session& s) {
    Session::pin(s.cpu(0));
    pthread_mutex_t m = PTHREAD_MUTEX_INITIALIZER;
    s.time_ops("peer_mutex_lock_unlock", "one thread pinned " + s.cpu_name(0) + ", default mutex",
               [&](std::uint64_t n) {
                   for (std::uint64_t i = 0; i < n; ++i) {
                       pthread_mutex_lock(&m);
                       pthread_mutex_unlock(&m);
                   }
               });
    pthread_mutex_destroy(&m);
}
CHM_BENCH_MEASUREMENT(mutex_uncontended, "peer_mutex_lock_unlock");

void thread_sem_pingpong(Session& s) {
    const int cpu = s.cpu(0);
    Session::pin(cpu);
    sem_t ping, pong;
    check(sem_init(&ping, 0, 0) == 0 && sem_init(&pong, 0, 0) == 0, "sem_init");
    std::atomic<bool> stop{false};
    {
        Partner partner(
            cpu,
            [&] {
                for (;;) {
                    while (sem_wait(&ping) != 0) {
                    }
                    if (stop.load()) return;
                    sem_post(&pong);
                }
            },
            [&] {
                stop = true;
                sem_post(&ping);
            });
        s.time_ops("peer_thread_sem_pingpong_same_core",
                   "two threads pinned " + s.cpu_name(0) + ", SCHED_OTHER; RT/2",
                   [&](std::uint64_t n) {
                       for (std::uint64_t i = 0; i < n; ++i) {
                           sem_post(&ping);
                           while (sem_wait(&pong) != 0) eintr_or_fail("sem_wait");
                       }
                   },
                   2);
    }
    sem_destroy(&ping);
    sem_destroy(&pong);
}
CHM_BENCH_MEASUREMENT(thread_sem_pingpong, "peer_thread_sem_pingpong_same_core");

}  // namespace
}  // namespace chm::bench
