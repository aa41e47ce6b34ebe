// Peer: a pipe ping-pong between two processes, the oldest cross-process
// wake-up there is.
#include <unistd.h>

#include <cstdint>

#include "../harness.hpp"
#include "../proc.hpp"

namespace chm::bench {
namespace {

struct Pipe {
    Pipe() { check(pipe(fd) == 0, "pipe"); }
    ~Pipe() {
        close(fd[0]);
        close(fd[1]);
    }
    Pipe(const Pipe&) = delete;
    Pipe& operator=(const Pipe&) = delete;
    int fd[2];
};

void pipe_pingpong(Session& s) {
    for_both_pinnings(s, "peer_pipe_pingpong", "processes", [&](const std::string& row, const Pinning& p) {
        Pipe down, up;
        Child child(p.other, [&] {
            char c;
            for (;;) {
                if (read(down.fd[0], &c, 1) != 1) return 1;
                if (write(up.fd[1], &c, 1) != 1) return 1;
            }
        });
        s.time_ops(row, p.text + ", 1-byte read/write, SCHED_OTHER; RT/2",
                   [&](std::uint64_t n) {
                       char c = 'x';
                       for (std::uint64_t i = 0; i < n; ++i) {
                           while (write(down.fd[1], &c, 1) != 1) eintr_or_fail("write(pipe)");
                           // We hold both write ends, so read never sees EOF.
                           while (read(up.fd[0], &c, 1) != 1) eintr_or_fail("read(pipe)");
                       }
                   },
                   2);
    });
}
CHM_BENCH_MEASUREMENT(pipe_pingpong, "peer_pipe_pingpong_same_core", "peer_pipe_pingpong_xcore");

}  // namespace
}  // namespace chm::bench
