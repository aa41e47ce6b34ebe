// Peer: ucontext swapcontext, the portable switch (it saves the signal mask
// with a system call each time, which is why it is slow).
#include <ucontext.h>

#include <cstdint>
#include <vector>

#include "../harness.hpp"

namespace chm::bench {
namespace {

ucontext_t g_main, g_other;

void other_entry() {
    for (;;) swapcontext(&g_other, &g_main);
}

void ucontext_switch(Session& s) {
    Session::pin(s.cpu(0));
    std::vector<unsigned char> stack(64 * 1024);
    check(getcontext(&g_other) == 0, "getcontext");
    g_other.uc_stack.ss_sp = stack.data();
    g_other.uc_stack.ss_size = stack.size();
    g_other.uc_link = nullptr;
    makecontext(&g_other, other_entry, 0);
    // The other context is left suspended for good; its stack dies with it.
    s.time_ops("peer_ucontext_switch", "pinned " + s.cpu_name(0),
               [&](std::uint64_t n) {
                   for (std::uint64_t i = 0; i < n; ++i) swapcontext(&g_main, &g_other);
               },
               2);
}
CHM_BENCH_MEASUREMENT(ucontext_switch, "peer_ucontext_switch");

}  // namespace
}  // namespace chm::bench
