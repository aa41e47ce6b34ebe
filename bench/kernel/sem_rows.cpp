// Table 1, local semaphores, and the semaphore performance targets. Every row
// times its own operation:
//  * uncontended P, V and P+V: batches on CLOCK_MONOTONIC in one task;
//  * P that blocks, V that wakes (with and without the switch), and the
//    resource-contention reschedule: intervals that start in one task and
//    end in another, read with the inline cycle clock (kbench.hpp) at the
//    last instruction before the call and the first one after it in the
//    task that runs next; the cost of a clock read is subtracted.
// The default configuration (kbench.hpp) unless a row says otherwise.
#include "kbench.hpp"

namespace chm::bench {
namespace {

using kb::ticks;

std::string where(Session& s) { return kb::pinned(s) + ", " + kb::kDefaultConfig; }

// ---- uncontended: one task, a counting semaphore
void pv_rows(Session& s) {
    Session::pin(s.cpu(0));
    kb::Kernel k;
    chm_sem_t sem;
    (void)chm_sem_init(&sem, CHM_SEM_COUNTING, 1, 0);
    std::function<void()> body = [&] {
        const std::string w = where(s) + ", counting semaphore";
        s.time_ops("local_pv_noblock", w + "; chm_sem_p + chm_sem_v, count 1", [&](std::uint64_t n) {
            for (std::uint64_t i = 0; i < n; ++i) {
                (void)chm_sem_p(&sem);
                (void)chm_sem_v(&sem);
            }
        });
        s.time_custom("local_p_noblock", w + "; chm_sem_p with units available (given back untimed)",
                      [&](std::uint64_t n) {
                          for (std::uint64_t i = 0; i < n; ++i) (void)chm_sem_v(&sem);
                          const std::uint64_t t0 = mono_ns();
                          for (std::uint64_t i = 0; i < n; ++i) (void)chm_sem_p(&sem);
                          return double(mono_ns() - t0);
                      });
        s.time_custom("local_v_nowake", w + "; chm_sem_v with nobody waiting (taken back untimed)",
                      [&](std::uint64_t n) {
                          const std::uint64_t t0 = mono_ns();
                          for (std::uint64_t i = 0; i < n; ++i) (void)chm_sem_v(&sem);
                          const double t = double(mono_ns() - t0);
                          for (std::uint64_t i = 0; i < n; ++i) (void)chm_sem_p(&sem);
                          return t;
                      });
    };
    kb::spawn_fn(&body, {});
    k.run();
    (void)chm_sem_destroy(&sem);
}
CHM_BENCH_MEASUREMENT(pv_rows, "local_pv_noblock", "local_p_noblock", "local_v_nowake");

// ---- H (priority 10) and L (1) hand a binary semaphore back and forth:
// H's P blocks and L runs (local_p_block); L's V wakes H, which runs at
// once (sem_v_wake_switch). Both intervals are read separately.
struct PingPong {
    chm_sem_t sem;
    volatile std::uint64_t stamp_h = 0, stamp_l = 0;
    std::uint64_t l_sum = 0;
    volatile bool stop = false;
};

void pp_low(void* p) {
    auto* a = static_cast<PingPong*>(p);
    while (!a->stop) {
        const std::uint64_t t = ticks();  // first instruction after H blocked
        a->l_sum += t - a->stamp_h;
        a->stamp_l = ticks();
        (void)chm_sem_v(&a->sem);
    }
}

struct PingPongFigures {
    Stats p_block, v_wake_switch;
};

PingPongFigures pingpong(Session& s, const kb::KernelOpts& o) {
    kb::Kernel k(o);
    const kb::TickClock& clk = kb::tick_clock();
    PingPong a;
    (void)chm_sem_init(&a.sem, CHM_SEM_BINARY, 0, 0);
    PingPongFigures f;
    std::function<void()> high = [&] {
        auto round = [&] {
            a.stamp_h = ticks();
            (void)chm_sem_p(&a.sem);
            return ticks() - a.stamp_l;  // first instruction after L's V
        };
        f.v_wake_switch = s.measure([&](std::uint64_t n) {
            std::uint64_t sum = 0;
            for (std::uint64_t i = 0; i < n; ++i) sum += round();
            return clk.ns(sum) - double(n) * clk.pair_ns;
        });
        f.p_block = s.measure([&](std::uint64_t n) {
            a.l_sum = 0;
            for (std::uint64_t i = 0; i < n; ++i) round();
            return clk.ns(a.l_sum) - double(n) * clk.pair_ns;
        });
        a.stop = true;
    };
    kb::TaskSpec hi;
    hi.priority = 10;
    kb::spawn_fn(&high, hi);
    kb::spawn(pp_low, &a, 1);
    k.run();
    (void)chm_sem_destroy(&a.sem);
    return f;
}

void wake_switch_rows(Session& s) {
    Session::pin(s.cpu(0));
    const PingPongFigures dflt = pingpong(s, {});
    const PingPongFigures fixed = pingpong(s, {CHM_SCHED_FIXED, 1, 0});
    const PingPongFigures f = pingpong(s, {CHM_SCHED_FIXED, 0, 0});
    const std::string clock = "; " + kb::tick_clock().name + " read at the call and at the first "
                              "instruction of the task that runs next, its own cost subtracted";
    // The default configuration is the figure; the faster setting beside it.
    s.emit("sem_v_wake_switch",
           where(s) + "; binary semaphore: V by a priority-1 task waking a priority-10 task "
                      "blocked in P, until its P returns" + clock + "; FIXED policy, no quantum: " +
               kb::fmt_ns(fixed.v_wake_switch.median) + "; FIXED, no quantum, cpu_accounting 0 (charged at ticks "
               "only): " + kb::fmt_ns(f.v_wake_switch.median),
           dflt.v_wake_switch.median, dflt.v_wake_switch.min, dflt.v_wake_switch.max);
    s.emit("sem_v_wake_switch_vs_clocked_fiber",
           "sem_v_wake_switch's figure (default config) beside a fiber switch that charges CPU time, as "
           "cpu_accounting 1 (the default) must at the least",
           dflt.v_wake_switch.median, dflt.v_wake_switch.min, dflt.v_wake_switch.max);
    s.emit("local_p_block",
           where(s) + "; binary semaphore: P by a priority-10 task that blocks, until the "
                      "priority-1 task runs (it returns from its own V)" + clock,
           dflt.p_block.median, dflt.p_block.min, dflt.p_block.max);
}
CHM_BENCH_MEASUREMENT(wake_switch_rows, "sem_v_wake_switch", "sem_v_wake_switch_vs_clocked_fiber", "local_p_block");

// ---- V that wakes a blocked task of lower priority (no switch). H (10)
// times V(S) that wakes L (5), then blocks on B; L takes S and blocks on S
// again; Z (1), running only when both wait, gives B back to H.
struct Wake3 {
    chm_sem_t s, b;
    volatile bool stop = false;
};
void w3_low(void* p) {
    auto* a = static_cast<Wake3*>(p);
    for (;;) {
        (void)chm_sem_p(&a->s);
        if (a->stop) return;
    }
}
void w3_lowest(void* p) {
    auto* a = static_cast<Wake3*>(p);
    while (!a->stop) (void)chm_sem_v(&a->b);
}

void v_wake_row(Session& s) {
    Session::pin(s.cpu(0));
    kb::Kernel k;
    const kb::TickClock& clk = kb::tick_clock();
    Wake3 a;
    (void)chm_sem_init(&a.s, CHM_SEM_BINARY, 0, 0);
    (void)chm_sem_init(&a.b, CHM_SEM_BINARY, 0, 0);
    std::function<void()> high = [&] {
        s.time_custom("local_v_wake",
                      where(s) + "; binary semaphore: chm_sem_v by a priority-10 task waking a "
                                    "priority-5 task blocked in P (made ready, no switch); " +
                          clk.name + " around the call, its own cost subtracted",
                      [&](std::uint64_t n) {
                          std::uint64_t sum = 0;
                          for (std::uint64_t i = 0; i < n; ++i) {
                              const std::uint64_t t0 = ticks();
                              (void)chm_sem_v(&a.s);
                              sum += ticks() - t0;
                              (void)chm_sem_p(&a.b);  // L blocks again, Z gives b back
                          }
                          return clk.ns(sum) - double(n) * clk.pair_ns;
                      });
        a.stop = true;
        (void)chm_sem_v(&a.s);
    };
    kb::TaskSpec hi;
    hi.priority = 10;
    kb::spawn_fn(&high, hi);
    kb::spawn(w3_low, &a, 5);
    kb::spawn(w3_lowest, &a, 1);
    k.run();
    (void)chm_sem_destroy(&a.s);
    (void)chm_sem_destroy(&a.b);
}
CHM_BENCH_MEASUREMENT(v_wake_row, "local_v_wake");

// ---- resource contention: L (1) holds M (binary, priority inheritance)
// and wakes H (10) through G; H's P(M) blocks, L inherits H's urgency and
// runs, its V(M) gives M to H, drops the inheritance and switches back.
struct Contention {
    chm_sem_t m, g;
    volatile bool stop = false;
};
void ct_low(void* p) {
    auto* a = static_cast<Contention*>(p);
    while (!a->stop) {
        (void)chm_sem_p(&a->m);
        (void)chm_sem_v(&a->g);  // H runs, blocks on m; we come back here boosted
        (void)chm_sem_v(&a->m);
    }
}

void contention_row(Session& s) {
    Session::pin(s.cpu(0));
    kb::Kernel k;
    const kb::TickClock& clk = kb::tick_clock();
    Contention a;
    (void)chm_sem_init(&a.m, CHM_SEM_BINARY, 1, CHM_SEM_INHERIT);
    (void)chm_sem_init(&a.g, CHM_SEM_BINARY, 0, 0);
    std::function<void()> high = [&] {
        s.time_custom("resource_contention_resched",
                      where(s) + "; chm_sem_p by a priority-10 task on a binary semaphore "
                                    "(CHM_SEM_INHERIT) held by a priority-1 task: block, lend the "
                                    "holder its urgency, switch to it, the holder's V hands the "
                                    "unit over, drops the inheritance and switches back, until P "
                                    "returns; " +
                          clk.name + " around the P, its own cost subtracted",
                      [&](std::uint64_t n) {
                          std::uint64_t sum = 0;
                          for (std::uint64_t i = 0; i < n; ++i) {
                              (void)chm_sem_p(&a.g);  // L now holds m
                              const std::uint64_t t0 = ticks();
                              (void)chm_sem_p(&a.m);
                              sum += ticks() - t0;
                              (void)chm_sem_v(&a.m);
                          }
                          return clk.ns(sum) - double(n) * clk.pair_ns;
                      });
        a.stop = true;
    };
    kb::TaskSpec hi;
    hi.priority = 10;
    kb::spawn_fn(&high, hi);
    kb::spawn(ct_low, &a, 1);
    k.run();
    (void)chm_sem_destroy(&a.m);
    (void)chm_sem_destroy(&a.g);
}
CHM_BENCH_MEASUREMENT(contention_row, "resource_contention_resched");

}  // namespace
}  // namespace chm::bench
