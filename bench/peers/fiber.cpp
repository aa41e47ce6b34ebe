// Peer: Boost.Context `fiber`, the user-space switch a C++ user would pick.
// Its switch is the yardstick of the port's switch and of yield_switch; its
// create+run+destroy stands beside task_spawn_run_exit (task_spawn_run_exit_vs_fiber).
//
// The clocked variants are the same fibers charging each other their CPU
// time at every switch, as a kernel that accounts CPU time per switch (the
// default: cpu_accounting 1) must at the least: one read of the cycle
// counter and an add per switch, no conversion. They are the in-run floor
// of yield_switch, sem_v_wake_switch and task_spawn_run_exit under that
// default (the *_vs_clocked_fiber rows): on a machine where one counter
// read costs more than a fiber switch, 3 x a plain fiber switch is out of
// reach of any scheduler that charges CPU time exactly.
#include <boost/context/fiber.hpp>
#include <boost/context/pooled_fixedsize_stack.hpp>

#include <cstdint>
#include <memory>
#include <stdexcept>

#include "../harness.hpp"
#include "../kernel/kbench.hpp"  // kb::ticks: the cycle counter, read inline

namespace ctx = boost::context;

namespace chm::bench {
namespace {

void fiber_switch(Session& s) {
    Session::pin(s.cpu(0));
    bool stop = false;
    ctx::fiber f{[&stop](ctx::fiber&& back) {
        while (!stop) back = std::move(back).resume();
        return std::move(back);
    }};
    // One iteration = into the fiber and back = two switches.
    s.time_ops("peer_fiber_switch", "pinned " + s.cpu_name(0) + ", default fixedsize stack",
               [&](std::uint64_t n) {
                   for (std::uint64_t i = 0; i < n; ++i) f = std::move(f).resume();
               },
               2);
    stop = true;
    f = std::move(f).resume();  // lets the fiber return: it ends cleanly
}
CHM_BENCH_MEASUREMENT(fiber_switch, "peer_fiber_switch");

void fiber_create_destroy(Session& s) {
    Session::pin(s.cpu(0));
    // A pool, as a task pool would: a fresh mmap per fiber measures the
    // kernel's page faults, not Boost (see peer_mmap_stack_64k_*).
    ctx::pooled_fixedsize_stack pool(64 * 1024);
    std::uint64_t ran = 0;
    s.time_ops("peer_fiber_create_destroy",
               "pinned " + s.cpu_name(0) + ", pooled 64 KiB stacks, entered once and ended",
               [&](std::uint64_t n) {
                   for (std::uint64_t i = 0; i < n; ++i) {
                       ctx::fiber f{std::allocator_arg, pool, [&ran](ctx::fiber&& back) {
                                        ++ran;
                                        return std::move(back);
                                    }};
                       f = std::move(f).resume();  // runs to its end; f is empty again
                   }
               });
    if (ran == 0) throw std::runtime_error("fiber never ran");
}
CHM_BENCH_MEASUREMENT(fiber_create_destroy, "peer_fiber_create_destroy");

// The fiber switch with per-switch CPU accounting: each side reads the
// cycle counter when it switches away and charges the time since the last
// switch to itself.
void fiber_switch_clocked(Session& s) {
    Session::pin(s.cpu(0));
    bool stop = false;
    std::uint64_t last = kb::ticks(), cpu_main = 0, cpu_fiber = 0;
    ctx::fiber f{[&](ctx::fiber&& back) {
        while (!stop) {
            const std::uint64_t t = kb::ticks();
            cpu_fiber += t - last;
            last = t;
            back = std::move(back).resume();
        }
        return std::move(back);
    }};
    s.time_ops("peer_fiber_switch_clocked",
               "pinned " + s.cpu_name(0) + ", default fixedsize stack; at every switch the side leaving "
               "reads the cycle counter and charges itself the time since the last switch",
               [&](std::uint64_t n) {
                   for (std::uint64_t i = 0; i < n; ++i) {
                       const std::uint64_t t = kb::ticks();
                       cpu_main += t - last;
                       last = t;
                       f = std::move(f).resume();
                   }
               },
               2);
    stop = true;
    f = std::move(f).resume();
    if (cpu_main + cpu_fiber == 0) throw std::runtime_error("clocked fiber charged nothing");
}
CHM_BENCH_MEASUREMENT(fiber_switch_clocked, "peer_fiber_switch_clocked");

// Create + run + destroy with the same accounting: the creator charges
// itself when it switches in, the fiber when it ends and switches back.
void fiber_create_destroy_clocked(Session& s) {
    Session::pin(s.cpu(0));
    ctx::pooled_fixedsize_stack pool(64 * 1024);
    std::uint64_t last = kb::ticks(), cpu_main = 0, cpu_fibers = 0;
    s.time_ops("peer_fiber_create_destroy_clocked",
               "pinned " + s.cpu_name(0) + ", pooled 64 KiB stacks, entered once and ended; at each of "
               "its two switches the side leaving reads the cycle counter and charges itself",
               [&](std::uint64_t n) {
                   for (std::uint64_t i = 0; i < n; ++i) {
                       ctx::fiber f{std::allocator_arg, pool, [&](ctx::fiber&& back) {
                                        const std::uint64_t t = kb::ticks();
                                        cpu_fibers += t - last;
                                        last = t;
                                        return std::move(back);
                                    }};
                       const std::uint64_t t = kb::ticks();
                       cpu_main += t - last;
                       last = t;
                       f = std::move(f).resume();
                   }
               });
    if (cpu_main + cpu_fibers == 0) throw std::runtime_error("clocked fiber charged nothing");
}
CHM_BENCH_MEASUREMENT(fiber_create_destroy_clocked, "peer_fiber_create_destroy_clocked");

}  // namespace
}  // namespace chm::bench
