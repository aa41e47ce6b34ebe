// Remote semaphore rows: P and V with nobody waiting (one robust backplane
// lock, no system call), and the hand-off between two host processes that
// sleep on the grant word's futex, against the raw shared futex ping-pong.
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <string>
#include <unistd.h>

#include "../harness.hpp"
#include "../proc.hpp"
#include "rtpu.hpp"
#include "chimera/bp.h"
#include "chimera/rsem.h"
#include "chimera/shm.h"

namespace chm::bench {
namespace {

// A private backplane for one measurement (ipcb::BackplaneFile, rtpu.hpp),
// attached as a host; removed on every path out.
struct Backplane {
    ipcb::BackplaneFile file{"rsem", 8};
    Backplane() {
        if (chm_bp_attach_host(file.path.c_str(), "bench", nullptr) != 0)
            fail(std::string("chm_bp_attach_host: ") + chm_bp_last_error());
    }
    ~Backplane() { (void)chm_bp_leave(); }
    chm_rsem_t* sem(const char* name, uint32_t initial) {
        chm_rsem_t* s = nullptr;
        if (chm_rsem_create(name, CHM_SEM_COUNTING, initial, CHM_SHM_COMMON, &s) != 0)
            fail(std::string("chm_rsem_create: ") + chm_bp_last_error());
        return s;
    }
    static void fail(const std::string& why) {
        std::fprintf(stderr, "rsem rows: %s\n", why.c_str());
        _exit(3);
    }
};

void rsem_noblock(Session& s) {
    Session::pin(s.cpu(0));
    Backplane bp;
    chm_rsem_t* sem = bp.sem("noblock", 0x7fffffff);
    const std::string cfg = "pinned " + s.cpu_name(0) + ", host process, counting semaphore in common memory";
    s.time_ops("remote_semp_noblock", cfg + "; P on a positive count", [&](std::uint64_t n) {
        for (std::uint64_t i = 0; i < n; ++i) (void)chm_rsem_p(sem);
    });
    s.time_ops("remote_semv_nowake", cfg + "; V with nobody waiting", [&](std::uint64_t n) {
        for (std::uint64_t i = 0; i < n; ++i) (void)chm_rsem_v(sem);
    });
}
CHM_BENCH_MEASUREMENT(rsem_noblock, "remote_semp_noblock", "remote_semv_nowake");

// V until given: -EBUSY (its 10 ms bound for the lock ran out, rsem.h)
// gave nothing, and a lost unit would stop the ping-pong for good.
void v_given(chm_rsem_t* s) {
    while (chm_rsem_v(s) == -EBUSY) {
    }
}

void rsem_handoff(Session& s) {
    const int cpu = s.cpu(0);
    Session::pin(cpu);
    Backplane bp;
    chm_rsem_t* ping = bp.sem("ping", 0);
    chm_rsem_t* pong = bp.sem("pong", 0);
    const std::string path = bp.file.path;
    Child child(cpu, [path] {
        // A forked child does not inherit the attachment: attach anew.
        if (chm_bp_attach_host(path.c_str(), "partner", nullptr) != 0) return 2;
        chm_rsem_t *pi = nullptr, *po = nullptr;
        if (chm_rsem_open("ping", &pi) != 0 || chm_rsem_open("pong", &po) != 0) return 3;
        for (;;) {
            if (chm_rsem_p(pi) != 0) return 4;
            v_given(po);
        }
    });
    s.time_ops("rsem_handoff_sleeping_host_processes",
               "same core (" + s.cpu_name(0) +
                   "), two host processes, each sleeping on its waiter record's futex; RT/2",
               [&](std::uint64_t n) {
                   for (std::uint64_t i = 0; i < n; ++i) {
                       v_given(ping);
                       (void)chm_rsem_p(pong);
                   }
               },
               2);
}
CHM_BENCH_MEASUREMENT(rsem_handoff, "rsem_handoff_sleeping_host_processes");

}  // namespace
}  // namespace chm::bench
