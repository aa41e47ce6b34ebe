// Peer: POSIX message queues (mq_open), the standard priority message queue
// a user would pick instead of Chimera's: a 24-byte round trip between two
// processes (judged against msgq_wake_rt2) and send+receive in one thread.
#include <fcntl.h>
#include <mqueue.h>

#include <cstdint>
#include <cstring>

#include "../harness.hpp"
#include "../proc.hpp"

namespace chm::bench {
namespace {

constexpr std::size_t kMsg = 24;  // the paper's message size

// Unlinked as soon as it is open; the child inherits the descriptor.
struct Queue {
    explicit Queue(const char* what) {
        const std::string name = ipc_name(what);
        mq_attr attr{};
        attr.mq_maxmsg = 8;  // within Linux's default msg_max of 10
        attr.mq_msgsize = kMsg;
        q = mq_open(name.c_str(), O_RDWR | O_CREAT | O_EXCL, 0600, &attr);
        check(q != mqd_t(-1), "mq_open");
        mq_unlink(name.c_str());
    }
    ~Queue() { mq_close(q); }
    Queue(const Queue&) = delete;
    Queue& operator=(const Queue&) = delete;
    mqd_t q;
};

void posix_mq_rt2(Session& s) {
    for_both_pinnings(s, "peer_posix_mq_24b_rt2", "processes", [&](const std::string& row, const Pinning& p) {
        Queue down("down"), up("up");
        Child child(p.other, [&] {
            char buf[kMsg];
            for (;;) {
                if (mq_receive(down.q, buf, sizeof buf, nullptr) != ssize_t(kMsg)) continue;
                mq_send(up.q, buf, kMsg, 0);
            }
            return 0;
        });
        s.time_ops(row, p.text + ", blocking mq_send/mq_receive, SCHED_OTHER; RT/2",
                   [&](std::uint64_t n) {
                       char buf[kMsg];
                       std::memset(buf, 7, sizeof buf);
                       for (std::uint64_t i = 0; i < n; ++i) {
                           while (mq_send(down.q, buf, kMsg, 0) != 0) eintr_or_fail("mq_send");
                           while (mq_receive(up.q, buf, sizeof buf, nullptr) != ssize_t(kMsg))
                               eintr_or_fail("mq_receive");
                       }
                   },
                   2);
    });
}
CHM_BENCH_MEASUREMENT(posix_mq_rt2, "peer_posix_mq_24b_rt2_same_core", "peer_posix_mq_24b_rt2_xcore");

void posix_mq_one_thread(Session& s) {
    Session::pin(s.cpu(0));
    Queue q("self");
    s.time_ops("peer_posix_mq_24b_one_thread", "one thread pinned " + s.cpu_name(0) +
                   ", the queue never blocks",
               [&](std::uint64_t n) {
                   char buf[kMsg];
                   std::memset(buf, 7, sizeof buf);
                   for (std::uint64_t i = 0; i < n; ++i) {
                       check(mq_send(q.q, buf, kMsg, 0) == 0, "mq_send");
                       check(mq_receive(q.q, buf, sizeof buf, nullptr) == ssize_t(kMsg), "mq_receive");
                   }
               });
}
CHM_BENCH_MEASUREMENT(posix_mq_one_thread, "peer_posix_mq_24b_one_thread");

}  // namespace
}  // namespace chm::bench
