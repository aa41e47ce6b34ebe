// What the backplane rows with real RTPUs share: a private backplane file
// (removed on every path out), the bench process joined as an RTPU with a
// kernel bound to its table entry, partner RTPUs in forked children, and a
// guard task on every RTPU so no wait on a peer outlives the measurement.
//
// Waits on another process are the hard part: a task parked in chm_rsem_p
// or chm_msgq_receive is not interrupted by the harness's watchdog or by a
// child's death (those only set flags). So every kernel here runs a guard
// task (highest priority, wakes every 20 ms) that stops the kernel when the
// harness wants to abort (parent) or when its time is up or the parent is
// gone (child). A failure inside a task is carried out of the kernel and
// rethrown by Kernel::run().
//
// Order in a measurement (destroyed in reverse, on every path):
//   BackplaneFile f;  Joined me(f.path, 1);  ... create objects ...
//   auto child = rtpu_child(...);           // fork before our kernel exists
//   Kernel k(1, poll);  k.spawn(&body, 10);  k.run();
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "../harness.hpp"
#include "../proc.hpp"
#include "chimera/bp.h"
#include "chimera/chimera.h"

namespace chm::bench::ipcb {

// A private backplane file in its own directory under /dev/shm (the tests'
// private_dir.hpp, as suites ipc and rtpu make theirs), created by the
// constructor; the destructor removes the directory and all in it.
struct BackplaneFile {
    std::string dir;
    std::string path;
    explicit BackplaneFile(const char* what, std::uint32_t slots = 10,
                           std::uint32_t window = 256 * 1024);
    ~BackplaneFile();
    BackplaneFile(const BackplaneFile&) = delete;
    BackplaneFile& operator=(const BackplaneFile&) = delete;
};

// This process joined as RTPU `slot` (chm_bp_join); left by the destructor.
struct Joined {
    Joined(const std::string& path, int slot);
    ~Joined();
    Joined(const Joined&) = delete;
    Joined& operator=(const Joined&) = delete;
};

// A kernel on the calling thread of a joined process: the default
// configuration (MUF, 1 ms quantum, CPU accounting), `idle_poll_ns`, its doorbell bound to the table entry, and the
// guard task. The destructor unbinds and tears it down.
class Kernel {
public:
    // `deadline_ns` (CLOCK_MONOTONIC, 0: none) and `parent` (0: none) are
    // the child's limits; the parent's guard watches abort_reason().
    Kernel(int slot, std::uint64_t idle_poll_ns, std::uint64_t deadline_ns = 0, int parent = 0);
    ~Kernel();
    Kernel(const Kernel&) = delete;
    Kernel& operator=(const Kernel&) = delete;
    // Spawn `fn` as a task of `priority` (1..999). An exception in it
    // stops the kernel and run() rethrows it; when every spawned task has
    // returned, the kernel stops. `fn` must outlive run().
    void spawn(std::function<void()>* fn, int priority, const char* name = nullptr);
    // The same for a task that never ends (a partner): not waited for.
    void spawn_endless(std::function<void()>* fn, int priority, const char* name = nullptr);
    // chm_kernel_run; rethrows what a task threw.
    void run();

private:
    bool bound_ = false;
};

// RTPU `slot` in a forked child pinned to `cpu` (-1: unpinned): joins,
// starts a Kernel with `idle_poll_ns`, lets `tasks` spawn its tasks and
// runs until they end, `limit_s` seconds pass, or the parent goes. The
// Child destructor kills and reaps it on every path.
std::unique_ptr<Child> rtpu_child(int cpu, const std::string& path, int slot,
                                  std::uint64_t idle_poll_ns, double limit_s,
                                  const std::function<void(Kernel&)>& tasks);

// Poll (bounded by the watchdog) until every slot in `slots` is RUNNING
// with its kernel bound (kernel thread published), on the backplane this
// process is attached to.
void wait_rtpus_running(const std::vector<int>& slots);

// Session::measure with one run aiming at `fraction` of the usual run
// length: for bodies that time only a small part of each iteration (a V
// inside a round of switches), so a row does not take 30 times the
// usual wall time. The text "median of R runs x N ops" goes to *how.
Stats measure_part(Session& s, double fraction, const std::function<double(std::uint64_t)>& body,
                   std::string* how = nullptr);

// Throw "what: chm_bp_last_error() (strerror)".
[[noreturn]] void fail_bp(const std::string& what, int r);

// The time limit of a partner RTPU: the watchdog's plus a margin.
double child_limit(const Session& s);

}  // namespace chm::bench::ipcb
