// State variables (issue 18): the cost of a cycle's copy-in and copy-out
// beside memcpy of the same bytes. A host process on a private backplane
// declares an input and an output of N doubles and makes a set of them;
// one operation is chm_svar_set_read + chm_svar_set_write (the framework's
// work around every module cycle), the peer two memcpy of N doubles
// between cache-resident buffers. Both run in turn, run by run
// (measure_interleaved), so they see the same machine.
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "../harness.hpp"
#include "chimera/bp.h"
#include "chimera/svar.h"
#include "rtpu.hpp"

namespace chm::bench {
namespace {

void copy_rows(Session& s, std::uint32_t n, const char* row, const char* peer) {
    Session::pin(s.cpu(0));
    ipcb::BackplaneFile f("svar");
    if (const int r = chm_bp_attach_host(f.path.c_str(), "bench", nullptr)) ipcb::fail_bp("chm_bp_attach_host", r);
    struct Leave {
        ~Leave() { (void)chm_bp_leave(); }
    } leave;
    chm_svar_decl_t in{"in", CHM_SVAR_DOUBLE, n, 1, ""}, out{"out", CHM_SVAR_DOUBLE, n, 1, ""};
    if (const int r = chm_svar_declare(&in)) ipcb::fail_bp("chm_svar_declare", r);
    if (const int r = chm_svar_declare(&out)) ipcb::fail_bp("chm_svar_declare", r);
    const char* ins[] = {"in"};
    const char* outs[] = {"out"};
    chm_svar_set_t* set = nullptr;
    if (const int r = chm_svar_set_create("bench", ins, 1, outs, 1, &set)) ipcb::fail_bp("chm_svar_set_create", r);
    std::vector<double> a(n, 1.0), b(n, 2.0), c(n, 3.0), d(n, 4.0);
    const std::size_t bytes = n * sizeof(double);
    auto svar = [&](std::uint64_t iters) {
        const std::uint64_t t0 = mono_ns();
        for (std::uint64_t i = 0; i < iters; ++i) {
            (void)chm_svar_set_read(set);
            (void)chm_svar_set_write(set);
        }
        return double(mono_ns() - t0);
    };
    auto copy = [&](std::uint64_t iters) {
        const std::uint64_t t0 = mono_ns();
        for (std::uint64_t i = 0; i < iters; ++i) {
            std::memcpy(a.data(), b.data(), bytes);
            asm volatile("" ::: "memory");  // keep every copy
            std::memcpy(c.data(), d.data(), bytes);
            asm volatile("" ::: "memory");
        }
        return double(mono_ns() - t0);
    };
    const auto [sv, mc] = s.measure_interleaved(svar, copy);
    (void)chm_svar_set_destroy(set);
    char cfg[300];
    std::snprintf(cfg, sizeof cfg,
                  "pinned %s, host process, default table; one set: input and output of %u doubles; "
                  "chm_svar_set_read + chm_svar_set_write per operation, run in turn with the peer",
                  s.cpu_name(0).c_str(), n);
    s.emit(row, cfg, sv.median, sv.min, sv.max);
    std::snprintf(cfg, sizeof cfg, "pinned %s; two memcpy of %zu bytes between cache-resident buffers",
                  s.cpu_name(0).c_str(), bytes);
    s.emit(peer, cfg, mc.median, mc.min, mc.max);
}

void svar_rows(Session& s) {
    copy_rows(s, 64, "svar_copy_in_out_64d", "peer_memcpy_1kib");
    copy_rows(s, 1024, "svar_copy_in_out_1024d", "peer_memcpy_16kib");
}
CHM_BENCH_MEASUREMENT(svar_rows, "svar_copy_in_out_64d", "peer_memcpy_1kib", "svar_copy_in_out_1024d",
                      "peer_memcpy_16kib");

}  // namespace
}  // namespace chm::bench
