// Global shared memory access overhead (Table 1: 0): the peer loops of
// peers/memory.hpp (sum_words, fill_words) run on a 64 KiB segment created
// and attached through chm_shm_* and, alternately in the same runs, on a
// 64 KiB local array. The row is the extra ns per 8-byte word (median of
// the per-run differences; may come out slightly negative), judged against
// the plain array figure (peer_array_read / peer_array_write).
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include "../harness.hpp"
#include "../kernel/kbench.hpp"  // kb::stats_of, kb::fmt_ns
#include "../peers/memory.hpp"
#include "chimera/bp.h"
#include "chimera/shm.h"
#include "rtpu.hpp"

namespace chm::bench {
namespace {

constexpr std::size_t kBytes = 64 * 1024;
constexpr std::size_t kWords = kBytes / 8;

// Attached as a host program (as any program using a segment would be).
struct Host {
    explicit Host(const std::string& path) {
        if (const int r = chm_bp_attach_host(path.c_str(), "bench", nullptr)) ipcb::fail_bp("chm_bp_attach_host", r);
    }
    ~Host() { (void)chm_bp_leave(); }
};

struct Segment {
    std::uint64_t* p = nullptr;
    Segment() {
        void* q = nullptr;
        if (const int r = chm_shm_create("bench.shm", kBytes, CHM_SHM_COMMON, &q)) ipcb::fail_bp("chm_shm_create", r);
        (void)chm_shm_detach(q);  // use it the way another process would: attach by name
        std::size_t size = 0;
        if (const int r = chm_shm_attach("bench.shm", &q, &size)) ipcb::fail_bp("chm_shm_attach", r);
        p = static_cast<std::uint64_t*>(q);
    }
    ~Segment() {
        (void)chm_shm_detach(p);
        (void)chm_shm_destroy("bench.shm");
    }
};

void shm_rows(Session& s) {
    Session::pin(s.cpu(0));
    ipcb::BackplaneFile f("shm");
    Host host(f.path);
    Segment seg;
    std::vector<std::uint64_t> local(kWords, 1);
    std::fill(seg.p, seg.p + kWords, 1);
    volatile std::uint64_t sink = 0;
    const std::string where = "pinned " + s.cpu_name(0) +
                              ", host process; a 64 KiB segment in common memory (chm_shm_create, then "
                              "chm_shm_attach by name) and a 64 KiB local array, cache-resident, "
                              "the same out-of-line loop on each (peers/memory.hpp), alternating "
                              "within every run; extra ns per 8-byte word = segment - array";
    for (const bool read : {true, false}) {
        auto pass = [&](std::uint64_t* p, std::uint64_t n) {
            const std::uint64_t t0 = mono_ns();
            for (std::uint64_t i = 0; i < n; ++i) {
                if (read) sink = sink + sum_words(p, kWords);
                else fill_words(p, kWords, i);
            }
            return double(mono_ns() - t0);
        };
        // Calibrate on the local array, then one run = both passes of n.
        const Stats cal = s.measure([&](std::uint64_t n) { return pass(local.data(), n); }, double(kWords));
        const std::uint64_t n = cal.iters_per_run;
        std::vector<double> diff, shm, arr;
        for (int r = 0; r < s.options().runs; ++r) {
            double ta, ts;
            if (r % 2) {
                ta = pass(local.data(), n);
                ts = pass(seg.p, n);
            } else {
                ts = pass(seg.p, n);
                ta = pass(local.data(), n);
            }
            const double per = double(n) * double(kWords);
            arr.push_back(ta / per);
            shm.push_back(ts / per);
            diff.push_back((ts - ta) / per);
            if (const char* why = abort_reason()) throw std::runtime_error(why);
        }
        const Stats d = kb::stats_of(diff), a = kb::stats_of(arr), g = kb::stats_of(shm);
        char b[200];
        std::snprintf(b, sizeof b, "; segment %.4f ns, array %.4f ns per word (medians); %d runs x %llu passes",
                      g.median, a.median, d.runs, static_cast<unsigned long long>(n));
        s.emit(read ? "shm_read_overhead" : "shm_write_overhead",
               where + (read ? "; sum_words (read)" : "; fill_words (write)") + b, d.median, d.min, d.max);
    }
}
CHM_BENCH_MEASUREMENT(shm_rows, "shm_read_overhead", "shm_write_overhead");

}  // namespace
}  // namespace chm::bench
