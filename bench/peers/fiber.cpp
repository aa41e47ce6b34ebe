// Peer: Boost.Context `fiber`, the user-space switch a C++ user would pick.
// Its switch is the yardstick of the port's switch and of yield_switch; its
// create+run+destroy stands beside task_spawn_run_exit (task_spawn_run_exit_vs_fiber).
#include <boost/context/fiber.hpp>
#include <boost/context/pooled_fixedsize_stack.hpp>

#include <cstdint>
#include <memory>

#include "../harness.hpp"

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

}  // namespace
}  // namespace chm::bench
