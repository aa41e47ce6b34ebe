// Message queue rows: the paper's 24-byte put and get with the queue in
// the caller's own RTPU window ("local") and in another RTPU's ("remote"),
// put+get with nobody waiting (judged against Boost message_queue in one
// thread), and a 24-byte ping-pong between two processes that sleep in
// receive (judged against POSIX mq, same pinning).
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <unistd.h>

#include "../harness.hpp"
#include "../proc.hpp"
#include "rtpu.hpp"
#include "chimera/bp.h"
#include "chimera/msgq.h"

namespace chm::bench {
namespace {

constexpr std::size_t kMsg = 24;
constexpr std::uint32_t kCapacity = 4096;
constexpr int kSelf = 1, kOther = 2;  // RTPU numbers: this process, the queue's home

// A private backplane for one measurement (ipcb::BackplaneFile, rtpu.hpp),
// joined as RTPU 1, removed on every path out.
struct Backplane {
    ipcb::BackplaneFile file{"msgq", 8, 1024 * 1024};  // room for a 4096-message queue
    Backplane() {
        if (chm_bp_join(file.path.c_str(), kSelf, "bench") != 0) fail(std::string("chm_bp_join: ") + chm_bp_last_error());
    }
    ~Backplane() { (void)chm_bp_leave(); }
    chm_msgq_t* queue(const char* name, int where, std::uint32_t count) {
        chm_msgq_attr_t a;
        chm_msgq_attr_init(&a);
        a.max_msg = kMsg;
        a.max_count = count;
        chm_msgq_t* q = nullptr;
        if (chm_msgq_create(name, &a, where, &q) != 0) fail(std::string("chm_msgq_create: ") + chm_bp_last_error());
        return q;
    }
    static void fail(const std::string& why) {
        std::fprintf(stderr, "msgq rows: %s\n", why.c_str());
        _exit(3);
    }
};

void put(chm_msgq_t* q, const char* buf) {
    if (chm_msgq_try_send(q, 1, 0, buf, kMsg) != 0) Backplane::fail("chm_msgq_try_send refused");
}
void get(chm_msgq_t* q, char* buf) {
    if (chm_msgq_try_receive(q, buf, kMsg, nullptr) != int(kMsg)) Backplane::fail("chm_msgq_try_receive refused");
}

void msgq_noblock(Session& s) {
    Session::pin(s.cpu(0));
    Backplane bp;
    const std::string where = "one process (RTPU 1) pinned " + s.cpu_name(0) + ", FIFO queue of 24-byte slots";
    char buf[kMsg];
    std::memset(buf, 7, sizeof buf);
    chm_msgq_t* remote = bp.queue("remote", kOther, kCapacity);
    s.time_ops("msgq_putget_24b_remote_one_process", where + " in RTPU 2's window; try_send + try_receive, never blocks",
               [&](std::uint64_t n) {
                   for (std::uint64_t i = 0; i < n; ++i) {
                       put(remote, buf);
                       get(remote, buf);
                   }
               });
    // The halves alone, in chunks the queue holds; the other half untimed.
    for (const bool local : {true, false}) {
        chm_msgq_t* q = local ? bp.queue("local", kSelf, kCapacity) : remote;
        const std::string cfg = where + (local ? " in its own window" : " in RTPU 2's window");
        // The queue in RTPU 2's window, but no process is RTPU 2: one process.
        const std::string tail = local ? "_local" : "_remote_one_process";
        s.time_custom("msg_put_24b" + tail, cfg + ", queue not full", [&](std::uint64_t n) {
            double ns = 0;
            for (std::uint64_t done = 0; done < n;) {
                const std::uint64_t k = std::min<std::uint64_t>(kCapacity, n - done);
                const std::uint64_t t0 = mono_ns();
                for (std::uint64_t i = 0; i < k; ++i) put(q, buf);
                ns += double(mono_ns() - t0);
                for (std::uint64_t i = 0; i < k; ++i) get(q, buf);
                done += k;
            }
            return ns;
        });
        s.time_custom("msg_get_24b" + tail, cfg + ", queue not empty", [&](std::uint64_t n) {
            double ns = 0;
            for (std::uint64_t done = 0; done < n;) {
                const std::uint64_t k = std::min<std::uint64_t>(kCapacity, n - done);
                for (std::uint64_t i = 0; i < k; ++i) put(q, buf);
                const std::uint64_t t0 = mono_ns();
                for (std::uint64_t i = 0; i < k; ++i) get(q, buf);
                ns += double(mono_ns() - t0);
                done += k;
            }
            return ns;
        });
    }
}
CHM_BENCH_MEASUREMENT(msgq_noblock, "msgq_putget_24b_remote_one_process", "msg_put_24b_local", "msg_get_24b_local",
                      "msg_put_24b_remote_one_process", "msg_get_24b_remote_one_process");

void msgq_wake(Session& s) {
    const int cpu = s.cpu(0);
    Session::pin(cpu);
    Backplane bp;
    chm_msgq_t* down = bp.queue("down", CHM_MSGQ_COMMON, 8);
    chm_msgq_t* up = bp.queue("up", CHM_MSGQ_COMMON, 8);
    const std::string path = bp.file.path;
    Child child(cpu, [path] {
        // A forked child does not inherit the attachment: join anew.
        if (chm_bp_join(path.c_str(), kOther, "partner") != 0) return 2;
        chm_msgq_t *d = nullptr, *u = nullptr;
        if (chm_msgq_open("down", &d) != 0 || chm_msgq_open("up", &u) != 0) return 3;
        char buf[kMsg];
        for (;;) {
            if (chm_msgq_receive(d, buf, sizeof buf, nullptr) != int(kMsg)) return 4;
            if (chm_msgq_send(u, 2, 0, buf, kMsg) != 0) return 5;
        }
    });
    const std::string config = "same core (" + s.cpu_name(0) +
                               "), two processes (RTPUs 1 and 2, no kernel), each sleeping in receive on "
                               "its waiter record's futex; RT/2";
    const auto round_trips = [&](std::uint64_t n) {
        char buf[kMsg];
        std::memset(buf, 7, sizeof buf);
        for (std::uint64_t i = 0; i < n; ++i) {
            if (chm_msgq_send(down, 1, 0, buf, kMsg) != 0) Backplane::fail("send");
            while (chm_msgq_receive(up, buf, sizeof buf, nullptr) != int(kMsg)) {
                if (const char* why = abort_reason()) Backplane::fail(why);
            }
        }
    };
    s.time_ops("msgq_wake_rt2_host_processes", config, round_trips, 2);
}
CHM_BENCH_MEASUREMENT(msgq_wake, "msgq_wake_rt2_host_processes");

}  // namespace
}  // namespace chm::bench
