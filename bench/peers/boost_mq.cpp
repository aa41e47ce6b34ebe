// Peer: Boost.Interprocess message_queue, the C++ shared-memory queue a user
// would pick instead of Chimera's message queues: 24-byte send+receive in one
// thread (the target for msgq_putget_24b_remote_one_process), send alone and receive alone
// (beside the paper's put and get), and a round trip between two processes.
#include <boost/date_time/posix_time/posix_time_types.hpp>
#include <boost/interprocess/ipc/message_queue.hpp>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <memory>
#include <vector>

#include "../harness.hpp"
#include "../proc.hpp"

namespace bip = boost::interprocess;

namespace chm::bench {
namespace {

constexpr std::size_t kMsg = 24;
constexpr std::size_t kCapacity = 4096;

// The name is removed as soon as the queue is mapped: a child forked later
// shares the mapping, and nothing is left in /dev/shm on any exit path.
std::unique_ptr<bip::message_queue> make_queue(const char* what, std::size_t capacity, std::size_t msg = kMsg) {
    const std::string name = ipc_name(what).substr(1);  // Boost adds the '/'
    bip::message_queue::remove(name.c_str());
    auto q = std::make_unique<bip::message_queue>(bip::create_only, name.c_str(), capacity, msg);
    bip::message_queue::remove(name.c_str());
    return q;
}

void bipc_mq_one_thread(Session& s) {
    Session::pin(s.cpu(0));
    const std::string where = "one thread pinned " + s.cpu_name(0);
    auto q = make_queue("self", kCapacity);
    char buf[kMsg];
    std::memset(buf, 7, sizeof buf);
    std::size_t got;
    unsigned prio;
    s.time_ops("peer_bipc_mq_24b_one_thread", where + ", the queue never blocks", [&](std::uint64_t n) {
        for (std::uint64_t i = 0; i < n; ++i) {
            q->send(buf, kMsg, 0);
            q->receive(buf, sizeof buf, got, prio);
        }
    });
    // The halves alone, in chunks the queue can hold; the other half untimed.
    s.time_custom("peer_bipc_mq_send_24b", where + ", queue not full", [&](std::uint64_t n) {
        double ns = 0;
        for (std::uint64_t done = 0; done < n;) {
            const std::uint64_t k = std::min<std::uint64_t>(kCapacity, n - done);
            const std::uint64_t t0 = mono_ns();
            for (std::uint64_t i = 0; i < k; ++i) q->send(buf, kMsg, 0);
            ns += double(mono_ns() - t0);
            for (std::uint64_t i = 0; i < k; ++i) q->receive(buf, sizeof buf, got, prio);
            done += k;
        }
        return ns;
    });
    s.time_custom("peer_bipc_mq_receive_24b", where + ", queue not empty", [&](std::uint64_t n) {
        double ns = 0;
        for (std::uint64_t done = 0; done < n;) {
            const std::uint64_t k = std::min<std::uint64_t>(kCapacity, n - done);
            for (std::uint64_t i = 0; i < k; ++i) q->send(buf, kMsg, 0);
            const std::uint64_t t0 = mono_ns();
            for (std::uint64_t i = 0; i < k; ++i) q->receive(buf, sizeof buf, got, prio);
            ns += double(mono_ns() - t0);
            done += k;
        }
        return ns;
    });
}
CHM_BENCH_MEASUREMENT(bipc_mq_one_thread, "peer_bipc_mq_24b_one_thread", "peer_bipc_mq_send_24b",
                      "peer_bipc_mq_receive_24b");

void bipc_mq_rt2(Session& s) {
    for_both_pinnings(s, "peer_bipc_mq_24b_rt2", "processes", [&](const std::string& row, const Pinning& p) {
        auto down = make_queue("down", 8);
        auto up = make_queue("up", 8);
        Child child(p.other, [&] {
            char buf[kMsg];
            std::size_t got;
            unsigned prio;
            for (;;) {
                down->receive(buf, sizeof buf, got, prio);
                up->send(buf, got, 0);
            }
            return 0;
        });
        s.time_ops(row, p.text + ", blocking send / timed_receive, SCHED_OTHER; RT/2",
                   [&](std::uint64_t n) {
                       // Condition-variable waits ignore EINTR: bound them by a
                       // deadline instead, computed once per run.
                       const auto deadline = boost::posix_time::microsec_clock::universal_time() +
                                             boost::posix_time::seconds(20);
                       char buf[kMsg];
                       std::memset(buf, 7, sizeof buf);
                       std::size_t got;
                       unsigned prio;
                       for (std::uint64_t i = 0; i < n; ++i) {
                           down->send(buf, kMsg, 0);
                           if (!up->timed_receive(buf, sizeof buf, got, prio, deadline))
                               throw std::runtime_error("message_queue: no reply from the peer process");
                       }
                   },
                   2);
    });
}
CHM_BENCH_MEASUREMENT(bipc_mq_rt2, "peer_bipc_mq_24b_rt2_same_core", "peer_bipc_mq_24b_rt2_xcore");

// Streaming between two processes on two cores, as msgq_stream_24b_xrtpu
// and msgq_stream_64k_xrtpu: `slots` slots of `msg` bytes, blocking send
// and receive, every message `msg` bytes, a run's last one answered on a
// second queue; ns per message.
void bipc_stream(Session& s, const char* row, std::size_t msg, std::size_t slots) {
    s.need_cpus(2);
    Session::pin(s.cpu(0));
    auto data = make_queue("data", slots, msg);
    auto ack = make_queue("ack", 4);
    Child child(s.cpu(1), [&] {
        std::vector<char> buf(msg);
        std::size_t got;
        unsigned prio;
        for (;;) {
            data->receive(buf.data(), buf.size(), got, prio);
            if (buf[0] == 1) ack->send(buf.data(), kMsg, 0);
        }
        return 0;
    });
    s.time_ops(row,
               "cross core: sender (this process) pinned " + s.cpu_name(0) + ", receiver (a forked "
               "process) pinned " + s.cpu_name(1) + ", SCHED_OTHER; " + std::to_string(slots) + " slots of " +
                   std::to_string(msg) + " bytes, blocking send / receive of " + std::to_string(msg) +
                   "-byte messages; per message, a run's last message answered on a second queue",
               [&](std::uint64_t n) {
                   const auto deadline = boost::posix_time::microsec_clock::universal_time() +
                                         boost::posix_time::seconds(20);
                   std::vector<char> buf(msg, 0);
                   char reply[kMsg];
                   std::size_t got;
                   unsigned prio;
                   for (std::uint64_t i = 0; i < n; ++i) {
                       buf[0] = i + 1 == n ? 1 : 0;
                       data->send(buf.data(), msg, 0);
                   }
                   if (!ack->timed_receive(reply, sizeof reply, got, prio, deadline))
                       throw std::runtime_error("message_queue: no answer from the peer process");
               });
}

void bipc_mq_stream(Session& s) { bipc_stream(s, "peer_bipc_mq_stream_24b_xcore", kMsg, 64); }
CHM_BENCH_MEASUREMENT(bipc_mq_stream, "peer_bipc_mq_stream_24b_xcore");

void bipc_mq_stream_64k(Session& s) { bipc_stream(s, "peer_bipc_mq_stream_64k_xcore", 64 * 1024, 8); }
CHM_BENCH_MEASUREMENT(bipc_mq_stream_64k, "peer_bipc_mq_stream_64k_xcore");

}  // namespace
}  // namespace chm::bench
