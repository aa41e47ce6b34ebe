// Peer: POSIX named semaphores between two processes (sem_open), the
// standard cross-process semaphore a user would reach for instead of a
// Chimera remote semaphore.
#include <fcntl.h>
#include <semaphore.h>

#include <cstdint>

#include "../harness.hpp"
#include "../proc.hpp"

namespace chm::bench {
namespace {

// The name is unlinked as soon as it is open: the child inherits the
// mapping through fork, and nothing is left behind on any exit path.
struct NamedSem {
    explicit NamedSem(const char* what) {
        const std::string name = ipc_name(what);
        sem = sem_open(name.c_str(), O_CREAT | O_EXCL, 0600, 0);
        check(sem != SEM_FAILED, "sem_open");
        sem_unlink(name.c_str());
    }
    ~NamedSem() { sem_close(sem); }
    NamedSem(const NamedSem&) = delete;
    NamedSem& operator=(const NamedSem&) = delete;
    sem_t* sem;
};

void named_sem_pingpong(Session& s) {
    for_both_pinnings(s, "peer_named_sem_pingpong", "processes", [&](const std::string& row, const Pinning& p) {
        NamedSem ping("ping"), pong("pong");
        Child child(p.other, [&] {
            for (;;) {
                while (sem_wait(ping.sem) != 0) {
                }
                sem_post(pong.sem);
            }
            return 0;
        });
        s.time_ops(row, p.text + ", sem_open semaphores, SCHED_OTHER; RT/2",
                   [&](std::uint64_t n) {
                       for (std::uint64_t i = 0; i < n; ++i) {
                           sem_post(ping.sem);
                           while (sem_wait(pong.sem) != 0) eintr_or_fail("sem_wait");
                       }
                   },
                   2);
    });
}
CHM_BENCH_MEASUREMENT(named_sem_pingpong, "peer_named_sem_pingpong_same_core",
                      "peer_named_sem_pingpong_xcore");

}  // namespace
}  // namespace chm::bench
