// Cost against the message size (24 B to 64 KiB): the data of
// docs/bench/scaling_msg_size.png and the rows msgq_putget_64k_remote_one_process /
// peer_bipc_mq_64k_one_thread. For each size, in one process pinned to one
// CPU, put+get with nobody waiting:
//   chimera_msgq_remote_one_process   chm_msgq_try_send + try_receive, this process joined
//                        as RTPU 1, the queue (4 slots of the size) in RTPU
//                        2's window (as msgq_putget_24b_remote_one_process)
//   boost_message_queue  Boost.Interprocess message_queue send + receive
//   posix_mq             mq_send + mq_receive (where the system's
//                        msgsize_max allows the size; null elsewhere)
//   memcpy_x2            two memcpy of the size: the copy in and out that
//                        every queue here does, the floor
#include <fcntl.h>
#include <mqueue.h>

#include <boost/interprocess/ipc/message_queue.hpp>

#include <cerrno>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <memory>
#include <string>
#include <vector>

#include "../harness.hpp"
#include "../kernel/kbench.hpp"  // kb::fmt_ns
#include "../proc.hpp"
#include "chimera/bp.h"
#include "chimera/msgq.h"
#include "rtpu.hpp"
#include "series.hpp"

namespace bip = boost::interprocess;

namespace chm::bench {
namespace {

constexpr std::uint32_t kSlots = 4;

[[gnu::noinline]] void copy2(void* a, void* b, const void* src, std::size_t n) {
    std::memcpy(a, src, n);
    std::memcpy(b, a, n);
}

void msg_size_scaling(Session& s) {
    Session::pin(s.cpu(0));
    const std::vector<std::size_t> sizes = {24, 64, 256, 1024, 4096, 16384, 65536};
    ipcb::BackplaneFile f("msgsize", 3, 1024 * 1024);  // room for 4 x 64 KiB in RTPU 2's window
    ipcb::Joined me(f.path, 1);
    std::vector<char> buf(65536, 7), out(65536), tmp(65536);
    ipcb::Series chm, boost, posix, copy;
    Stats chm64, boost64;
    std::string posix_note;
    for (const std::size_t size : sizes) {
        // Chimera: queue in another RTPU's window.
        chm_msgq_attr_t a;
        chm_msgq_attr_init(&a);
        a.max_msg = std::uint32_t(size);
        a.max_count = kSlots;
        chm_msgq_t* q = nullptr;
        const std::string qname = "size" + std::to_string(size);
        if (const int r = chm_msgq_create(qname.c_str(), &a, 2, &q)) ipcb::fail_bp("chm_msgq_create", r);
        const Stats c = s.measure([&](std::uint64_t n) {
            const std::uint64_t t0 = mono_ns();
            for (std::uint64_t i = 0; i < n; ++i) {
                if (chm_msgq_try_send(q, 1, 0, buf.data(), size) != 0) throw std::runtime_error("chm_msgq_try_send");
                if (chm_msgq_try_receive(q, out.data(), size, nullptr) != int(size))
                    throw std::runtime_error("chm_msgq_try_receive");
            }
            return double(mono_ns() - t0);
        });
        (void)chm_msgq_close(q);
        (void)chm_msgq_destroy(qname.c_str());
        chm.add(c);
        // Boost.Interprocess message_queue, its name removed once mapped.
        {
            const std::string name = ipc_name("msgsize").substr(1);
            bip::message_queue::remove(name.c_str());
            auto bq = std::make_unique<bip::message_queue>(bip::create_only, name.c_str(), kSlots, size);
            bip::message_queue::remove(name.c_str());
            std::size_t got;
            unsigned prio;
            const Stats b = s.measure([&](std::uint64_t n) {
                const std::uint64_t t0 = mono_ns();
                for (std::uint64_t i = 0; i < n; ++i) {
                    bq->send(buf.data(), size, 0);
                    bq->receive(out.data(), size, got, prio);
                }
                return double(mono_ns() - t0);
            });
            boost.add(b);
            if (size == 65536) {
                chm64 = c;
                boost64 = b;
            }
        }
        // POSIX mq, where the size is allowed.
        {
            const std::string name = ipc_name("msgsize");
            mq_unlink(name.c_str());
            mq_attr attr{};
            attr.mq_maxmsg = kSlots;
            attr.mq_msgsize = long(size);
            const mqd_t m = mq_open(name.c_str(), O_RDWR | O_CREAT | O_EXCL, 0600, &attr);
            if (m == mqd_t(-1)) {
                if (posix_note.empty())
                    posix_note = "posix_mq from " + std::to_string(size) + " B: mq_open: " + std::strerror(errno);
                posix.add_null();
            } else {
                mq_unlink(name.c_str());
                unsigned prio;
                try {
                    posix.add(s.measure([&](std::uint64_t n) {
                        const std::uint64_t t0 = mono_ns();
                        for (std::uint64_t i = 0; i < n; ++i) {
                            check(mq_send(m, buf.data(), size, 0) == 0, "mq_send");
                            check(mq_receive(m, out.data(), size, &prio) == ssize_t(size), "mq_receive");
                        }
                        return double(mono_ns() - t0);
                    }));
                } catch (...) {
                    mq_close(m);
                    throw;
                }
                mq_close(m);
            }
        }
        copy.add(s.measure([&](std::uint64_t n) {
            const std::uint64_t t0 = mono_ns();
            for (std::uint64_t i = 0; i < n; ++i) copy2(tmp.data(), out.data(), buf.data(), size);
            return double(mono_ns() - t0);
        }));
    }
    std::vector<double> xs(sizes.begin(), sizes.end());
    const std::string note = "\"config\": \"one process pinned " + s.cpu_name(0) +
                             ", put+get with nobody waiting, queues of 4 slots of the size\"" +
                             (posix_note.empty() ? std::string() : ", \"posix_mq_note\": \"" + posix_note + "\"");
    s.write_data("scaling_msg_size",
                 ipcb::series_json("bytes", xs, "series",
                                   {{"chimera_msgq_remote_one_process", chm}, {"boost_message_queue", boost},
                                    {"posix_mq", posix}, {"memcpy_x2", copy}},
                                   note));
    const std::string where = "one process pinned " + s.cpu_name(0) + ", 64 KiB messages, queue of 4 slots";
    s.emit("msgq_putget_64k_remote_one_process",
           where + " in RTPU 2's window (this process is RTPU 1); try_send + try_receive, never blocks; "
                   "two memcpy of 64 KiB alone: " + kb::fmt_ns(copy.median.back()),
           chm64.median, chm64.min, chm64.max);
    s.emit("peer_bipc_mq_64k_one_thread", where + "; send + receive in one thread, never blocks", boost64.median,
           boost64.min, boost64.max);
}
CHM_BENCH_MEASUREMENT(msg_size_scaling, "msgq_putget_64k_remote_one_process", "peer_bipc_mq_64k_one_thread");

}  // namespace
}  // namespace chm::bench
