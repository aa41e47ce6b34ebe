// Remote semaphore rows that block and wake, between tasks of real RTPUs
// (processes joined to a private backplane, each running a kernel whose
// doorbell is bound to its table entry):
//  * remote_semp_block: on one RTPU, a priority-10 task's chm_rsem_p blocks
//    (waiter record, park on the grant word) and the priority-1 task runs:
//    from the last instruction before the P to the first one of the task
//    that runs next, read with the inline cycle counter (as local_p_block);
//  * remote_semv_wake_local: chm_rsem_v by a priority-10 task waking a
//    priority-5 task of the same RTPU (made ready, no switch), around the
//    call (as local_v_wake);
//  * remote_semv_wake_remote: a task on RTPU 1 (this process, cpu A) Vs a
//    semaphore a task on RTPU 2 (a forked process, cpu B) waits on; that
//    one Vs another back: RT/2 of the ping-pong, both RTPUs sleeping when
//    idle (idle_poll_ns 0), beside the raw shared futex ping-pong across
//    cores;
//  * rsem_handoff_polling: the same ping-pong with idle_poll_ns on both
//    RTPUs: a waiting task with nothing else to run spins on its grant
//    word before it parks, so a V costs no ring, switch or system call on
//    either side; beside its floor, peer_cacheline_pingpong_rtpus: the
//    same two tasks passing one cache line, measured run by run in turn
//    with it (the host moves its vCPUs between placements whose line
//    transfer differs sevenfold, sometimes within a run: a floor measured
//    at another moment would be judged by the wrong one).
#include <atomic>
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <new>
#include <string>

#include "../harness.hpp"
#include "../kernel/kbench.hpp"  // kb::ticks, kb::tick_clock
#include "../peers/cacheline.hpp"
#include "chimera/bp.h"
#include "chimera/rsem.h"
#include "chimera/shm.h"
#include "port.hpp"  // the doorbell's ring counters
#include "rtpu.hpp"

namespace chm::bench {
namespace {

using kb::ticks;

constexpr std::uint64_t kPollNs = 100'000;  // rsem_handoff_polling: poll 100 us before sleeping

chm_rsem_t* make_sem(const char* name) {
    chm_rsem_t* s = nullptr;
    if (const int r = chm_rsem_create(name, CHM_SEM_COUNTING, 0, CHM_SHM_COMMON, &s))
        ipcb::fail_bp(std::string("chm_rsem_create ") + name, r);
    return s;
}

void check_rsem(int r, const char* what) {
    if (r != 0) ipcb::fail_bp(what, r);
}

// V as a user calls it: -EBUSY means its bounded wait for the lock (10 ms,
// rsem.h) ran out and the unit was not given, so it is called again. Only
// a holder stalled that long (a virtual CPU taken away) causes it; such an
// iteration is an outlier the medians do not see.
int rsem_v_given(chm_rsem_t* s) {
    int r;
    while ((r = chm_rsem_v(s)) == -EBUSY) {
    }
    return r;
}

std::string one_rtpu(Session& s) {
    return "one RTPU (this process, slot 1) pinned " + s.cpu_name(0) +
           ", default config (MUF, 1 ms quantum), idle_poll_ns 0, counting semaphore in common memory";
}

// ---- one RTPU: P that blocks, and the V that wakes it back with the switch
struct PingPong {
    chm_rsem_t* sem = nullptr;
    volatile std::uint64_t stamp_h = 0, stamp_l = 0;
    std::uint64_t l_sum = 0;
    volatile bool stop = false;
};

void rsem_block_rows(Session& s) {
    Session::pin(s.cpu(0));
    const kb::TickClock& clk = kb::tick_clock();
    ipcb::BackplaneFile f("rsem1");
    ipcb::Joined me(f.path, 1);
    PingPong a;
    a.sem = make_sem("pp");
    Stats p_block, v_switch;
    {
        ipcb::Kernel k(1, 0);
        std::function<void()> high = [&] {
            auto round = [&] {
                a.stamp_h = ticks();
                check_rsem(chm_rsem_p(a.sem), "chm_rsem_p");
                return ticks() - a.stamp_l;  // first instruction after L's V
            };
            // Only ~1/30 of each round is timed here: shorter runs.
            v_switch = ipcb::measure_part(s, 1.0 / 16, [&](std::uint64_t n) {
                std::uint64_t sum = 0;
                for (std::uint64_t i = 0; i < n; ++i) sum += round();
                return clk.ns(sum) - double(n) * clk.pair_ns;
            });
            p_block = s.measure([&](std::uint64_t n) {
                a.l_sum = 0;
                for (std::uint64_t i = 0; i < n; ++i) round();
                return clk.ns(a.l_sum) - double(n) * clk.pair_ns;
            });
            a.stop = true;
        };
        std::function<void()> low = [&] {
            while (!a.stop) {
                const std::uint64_t t = ticks();  // first instruction after H blocked
                a.l_sum += t - a.stamp_h;
                a.stamp_l = ticks();
                check_rsem(rsem_v_given(a.sem), "chm_rsem_v");
            }
        };
        k.spawn(&high, 10, "high");
        k.spawn(&low, 1, "low");
        k.run();
    }
    s.emit("remote_semp_block",
           one_rtpu(s) + "; chm_rsem_p by a priority-10 task on a count of 0: waiter record, park "
                         "on the grant word, switch to the priority-1 task, until its first "
                         "instruction; " + clk.name + " at both ends, its own cost subtracted; "
                         "the priority-1 task's chm_rsem_v waking it back, switch included: " +
               kb::fmt_ns(v_switch.median),
           p_block.median, p_block.min, p_block.max);
}
CHM_BENCH_MEASUREMENT(rsem_block_rows, "remote_semp_block");

// ---- one RTPU: V waking a lower-priority task (made ready, no switch).
// H (10) times V(S) waking L (5), then blocks on the local semaphore B; L
// takes S and blocks on S again; Z (1), running only when both wait, Vs B.
void rsem_wake_local_row(Session& s) {
    Session::pin(s.cpu(0));
    const kb::TickClock& clk = kb::tick_clock();
    ipcb::BackplaneFile f("rsem1w");
    ipcb::Joined me(f.path, 1);
    chm_rsem_t* sem = make_sem("wake");
    chm_sem_t b;
    (void)chm_sem_init(&b, CHM_SEM_BINARY, 0, 0);
    volatile bool stop = false;
    {
        ipcb::Kernel k(1, 0);
        std::function<void()> high = [&] {
            // Only the V (~1/40 of each round) is timed: shorter runs.
            std::string how;
            const Stats st = ipcb::measure_part(s, 1.0 / 32,
                          [&](std::uint64_t n) {
                              std::uint64_t sum = 0;
                              for (std::uint64_t i = 0; i < n; ++i) {
                                  const std::uint64_t t0 = ticks();
                                  check_rsem(rsem_v_given(sem), "chm_rsem_v");
                                  sum += ticks() - t0;
                                  (void)chm_sem_p(&b);  // L blocks again, Z gives b back
                              }
                              return clk.ns(sum) - double(n) * clk.pair_ns;
                          }, &how);
            s.emit("remote_semv_wake_local",
                   one_rtpu(s) + "; chm_rsem_v by a priority-10 task waking a priority-5 task of the "
                                 "same RTPU blocked in chm_rsem_p (grant stored, parked task made "
                                 "ready, no switch); " +
                       clk.name + " around the call, its own cost subtracted; " + how,
                   st.median, st.min, st.max);
            stop = true;
            check_rsem(rsem_v_given(sem), "chm_rsem_v");
        };
        std::function<void()> low = [&] {
            for (;;) {
                check_rsem(chm_rsem_p(sem), "chm_rsem_p");
                if (stop) return;
            }
        };
        std::function<void()> lowest = [&] {
            while (!stop) (void)chm_sem_v(&b);
        };
        k.spawn(&high, 10, "high");
        k.spawn(&low, 5, "low");
        k.spawn(&lowest, 1, "lowest");
        k.run();
    }
    (void)chm_sem_destroy(&b);
}
CHM_BENCH_MEASUREMENT(rsem_wake_local_row, "remote_semv_wake_local");

// ---- two RTPUs on two cores: a task on each hands two semaphores back
// and forth. RT/2 = a V on one RTPU until the task it wakes on the other
// runs.

using Floor = TaskLineFloor;  // ../peers/cacheline.hpp
Floor* floor_in(void* segment) { return task_line_floor_in(segment); }

// `n` hand-offs of the line and back (the bench's side); the partner's
// task is woken into answer_pings and back out by the two semaphores.
double pass_line(Floor& fl, chm_rsem_t* ping, chm_rsem_t* pong, std::uint64_t n) {
    fl.line.seq.store(0, std::memory_order_relaxed);
    fl.pass_line.store(1, std::memory_order_relaxed);
    check_rsem(rsem_v_given(ping), "chm_rsem_v");  // publishes both stores
    const double ns = send_pings(fl.line, n);
    fl.line.seq.store(kPingStop, std::memory_order_release);
    check_rsem(chm_rsem_p(pong), "chm_rsem_p");
    fl.pass_line.store(0, std::memory_order_relaxed);
    return ns;
}

// `floor_row` non-null: the row's floor measured with it, run by run in turn.
// `same_core`: RTPU 2 runs on RTPU 1's CPU (the sleeping hand-off, judged
// beside two processes on one core).
void rsem_xrtpu(Session& s, const std::string& row, std::uint64_t poll_ns, const std::string& mode,
                const char* floor_row = nullptr, bool same_core = false) {
    if (!same_core) s.need_cpus(2);
    Session::pin(s.cpu(0));
    const int other_cpu = same_core ? s.cpu(0) : s.cpu(1);
    const kb::TickClock& clk = kb::tick_clock();
    ipcb::BackplaneFile f("rsem2");
    ipcb::Joined me(f.path, 1);
    chm_rsem_t* ping = make_sem("ping");
    chm_rsem_t* pong = make_sem("pong");
    void* segment = nullptr;
    if (const int r = chm_shm_create("floor", sizeof(Floor) + 64, CHM_SHM_COMMON, &segment))
        ipcb::fail_bp("chm_shm_create floor", r);
    Floor& fl = *new (floor_in(segment)) Floor;
    auto child = ipcb::rtpu_child(other_cpu, f.path, 2, poll_ns, ipcb::child_limit(s), [](ipcb::Kernel& k) {
        static std::function<void()> body;
        body = [] {
            chm_rsem_t *pi = nullptr, *po = nullptr;
            void* seg = nullptr;
            std::size_t size = 0;
            check_rsem(chm_rsem_open("ping", &pi), "chm_rsem_open ping");
            check_rsem(chm_rsem_open("pong", &po), "chm_rsem_open pong");
            check_rsem(chm_shm_attach("floor", &seg, &size), "chm_shm_attach floor");
            Floor& fl = *floor_in(seg);
            for (;;) {
                check_rsem(chm_rsem_p(pi), "chm_rsem_p");
                if (fl.pass_line.load(std::memory_order_relaxed)) answer_pings(fl.line);
                check_rsem(rsem_v_given(po), "chm_rsem_v");
            }
        };
        k.spawn(&body, 10, "partner");
    });
    ipcb::wait_rtpus_running({2});
    Stats v_call;
    {
        ipcb::Kernel k(1, poll_ns);
        std::function<void()> body = [&] {
            const std::string cfg =
                std::string(same_core ? "same core" : "cross core") + ": RTPU 1 (this process) pinned " +
                s.cpu_name(0) + ", RTPU 2 (a forked process, its own kernel) pinned cpu" +
                std::to_string(other_cpu) + ", a priority-10 task on each, default config (MUF, 1 ms quantum), " + mode +
                "; counting semaphores in common memory; chm_rsem_v on one RTPU until the task it "
                "wakes on the other returns from chm_rsem_p; RT/2 of the ping-pong";
            // The caller's side alone: the V that grants and rings the other
            // RTPU; and how often a V rang and signalled it.
            const std::uint32_t rings0 = chm::port::doorbell_rings_sent();
            const std::uint32_t signals0 = chm::port::doorbell_signals_sent();
            std::uint64_t vs = 0;
            v_call = ipcb::measure_part(s, 0.25, [&](std::uint64_t n) {
                vs += n;
                std::uint64_t sum = 0;
                for (std::uint64_t i = 0; i < n; ++i) {
                    const std::uint64_t t0 = ticks();
                    check_rsem(rsem_v_given(ping), "chm_rsem_v");
                    sum += ticks() - t0;
                    check_rsem(chm_rsem_p(pong), "chm_rsem_p");
                }
                return clk.ns(sum) - double(n) * clk.pair_ns;
            });
            const auto per_v = [&](std::uint32_t count) {
                char b[32];
                std::snprintf(b, sizeof b, "%.3f", vs ? double(count) / double(vs) : 0.0);
                return std::string(b);
            };
            const std::string rang = "; per V on this side: " +
                                     per_v(chm::port::doorbell_rings_sent() - rings0) + " rings, " +
                                     per_v(chm::port::doorbell_signals_sent() - signals0) + " signals";
            const auto handoffs = [&](std::uint64_t n) {
                const std::uint64_t t0 = mono_ns();
                for (std::uint64_t i = 0; i < n; ++i) {
                    check_rsem(rsem_v_given(ping), "chm_rsem_v");
                    check_rsem(chm_rsem_p(pong), "chm_rsem_p");
                }
                return double(mono_ns() - t0);
            };
            const std::string what = cfg + "; the V call alone on the caller's side: " + kb::fmt_ns(v_call.median) + rang;
            if (!floor_row) {
                s.time_custom(row, what, handoffs, 2);
                return;
            }
            const auto [sem, line] = s.measure_interleaved(
                handoffs, [&](std::uint64_t n) { return pass_line(fl, ping, pong, n); }, 2);
            const std::string how = "; median of " + std::to_string(sem.runs) + " runs x " +
                                    std::to_string(sem.iters_per_run) + " iterations, each run followed by one of " +
                                    floor_row;
            s.emit(row, what + how, sem.median, sem.min, sem.max);
            s.emit(floor_row,
                   "the two tasks of " + row + " (RTPU 1 pinned " + s.cpu_name(0) + ", RTPU 2 pinned " +
                       s.cpu_name(1) + ") pass one cache line in common memory, spinning; RT/2; "
                       "each run follows one of " + row,
                   line.median, line.min, line.max);
        };
        k.spawn(&body, 10, "bench");
        k.run();
    }
}

void rsem_wake_remote_row(Session& s) {
    rsem_xrtpu(s, "remote_semv_wake_remote", 0,
               "idle_poll_ns 0 (an idle RTPU sleeps on its doorbell's futex at once: each wake-up is a "
               "futex wake of the other process)");
}
CHM_BENCH_MEASUREMENT(rsem_wake_remote_row, "remote_semv_wake_remote");

void rsem_polling_row(Session& s) {
    rsem_xrtpu(s, "rsem_handoff_polling", kPollNs,
               "idle_poll_ns " + std::to_string(kPollNs / 1000) +
                   " us on both (a task whose P must wait, with nothing else to run on its RTPU, "
                   "spins on its grant word that long before it parks: a V stores the grant and "
                   "rings nothing, no switch or system call on either side)",
               "peer_cacheline_pingpong_rtpus");
}
CHM_BENCH_MEASUREMENT(rsem_polling_row, "rsem_handoff_polling", "peer_cacheline_pingpong_rtpus");

// The hand-off to a sleeping RTPU through kernels on both ends (doorbell,
// grant, task switch), both RTPUs on one core as its peer's two processes.
void rsem_sleeping_row(Session& s) {
    rsem_xrtpu(s, "rsem_handoff_sleeping", 0,
               "idle_poll_ns 0 (an idle RTPU sleeps on its doorbell's futex at once)", nullptr,
               true);
}
CHM_BENCH_MEASUREMENT(rsem_sleeping_row, "rsem_handoff_sleeping");

}  // namespace
}  // namespace chm::bench
