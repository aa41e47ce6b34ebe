// chimera-bench: runs the registered measurements (every peer and every
// Chimera row that exists), joins their figures with the catalog, prints the
// table and writes the JSON that bench/run.py turns into docs/benchmarks.md.
//
//   chimera-bench [--quick] [--filter REGEX] [--json FILE]
//                 [--unmeasured-json FILE] [--samples DIR] [--cpus A,B] [--list]
#include <sched.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <regex>
#include <set>
#include <string>
#include <vector>

#include "catalog.hpp"
#include "harness.hpp"
#include "runner.hpp"

namespace chm::bench {
namespace {

struct Cli {
    Options opt;
    std::string json, unmeasured_json, filter;
    bool list = false;
};

[[noreturn]] void usage(int code) {
    std::fprintf(code ? stderr : stdout,
                 "usage: chimera-bench [--quick] [--filter REGEX] [--json FILE]\n"
                 "                     [--unmeasured-json FILE] [--samples DIR] [--cpus A,B] [--list]\n"
                 "  --quick            few short runs (whole suite well under a minute)\n"
                 "  --filter REGEX     only measurements producing a matching row (and their peers)\n"
                 "  --json FILE        write the measured rows as a JSON array\n"
                 "  --unmeasured-json FILE  catalog rows without a figure, with the reason\n"
                 "  --samples DIR      raw samples of distribution rows, one file per row\n"
                 "  --cpus A,B         the two CPUs to use (default: the first two allowed)\n"
                 "  --list             list the catalog and which rows can be measured\n");
    std::exit(code);
}

std::vector<int> allowed_cpus() {
    cpu_set_t set;
    std::vector<int> cpus;
    if (sched_getaffinity(0, sizeof set, &set) == 0)
        for (int c = 0; c < CPU_SETSIZE; ++c)
            if (CPU_ISSET(c, &set)) cpus.push_back(c);
    return cpus;
}

Cli parse(int argc, char** argv) {
    Cli cli;
    cli.opt.cpus = allowed_cpus();
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        auto value = [&]() -> std::string {
            if (i + 1 >= argc) usage(2);
            return argv[++i];
        };
        if (a == "--quick") cli.opt.quick = true;
        else if (a == "--json") cli.json = value();
        else if (a == "--unmeasured-json") cli.unmeasured_json = value();
        else if (a == "--filter") cli.filter = value();
        else if (a == "--samples") cli.opt.samples_dir = value();
        else if (a == "--list") cli.list = true;
        else if (a == "--cpus") {
            std::vector<int> cpus;
            const std::string v = value();
            for (std::size_t p = 0; p < v.size();) {
                const std::size_t q = v.find(',', p);
                cpus.push_back(std::atoi(v.substr(p, q - p).c_str()));
                p = q == std::string::npos ? v.size() : q + 1;
            }
            cli.opt.cpus = cpus;
        } else if (a == "--help" || a == "-h") usage(0);
        else usage(2);
    }
    if (cli.opt.quick) {
        // Enough to prove every row runs and to give a rough figure.
        cli.opt.runs = 21;
        cli.opt.warmup_runs = 2;
        cli.opt.run_ns = 1e6;
        cli.opt.watchdog_s = 30;
    }
    return cli;
}

// Every declared row is in the catalog and produced by one measurement only.
void validate_registry() {
    std::set<std::string> seen;
    for (const Measurement& m : registry())
        for (const std::string& r : m.rows) {
            if (!find_row(r)) {
                std::fprintf(stderr, "chimera-bench: %s declares row '%s' missing from the catalog\n",
                             m.fn_name, r.c_str());
                std::exit(3);
            }
            if (!seen.insert(r).second) {
                std::fprintf(stderr, "chimera-bench: row '%s' is declared twice\n", r.c_str());
                std::exit(3);
            }
        }
}

std::size_t first_row_index(const Measurement& m) {
    std::size_t i = catalog().size();
    for (const std::string& r : m.rows) i = std::min(i, row_index(r));
    return i;
}

int run(const Cli& cli) {
    validate_registry();
    std::vector<const Measurement*> all;
    for (const Measurement& m : registry()) all.push_back(&m);
    std::sort(all.begin(), all.end(), [](auto* a, auto* b) {
        return first_row_index(*a) < first_row_index(*b);
    });
    std::map<std::string, const Measurement*> producer;
    for (const Measurement* m : all)
        for (const std::string& r : m->rows) producer[r] = m;

    const std::regex re(cli.filter.empty() ? std::string(".*") : cli.filter);
    auto wanted = [&](const char* name) { return std::regex_search(name, re); };

    if (cli.list) {
        for (const RowInfo& r : catalog())
            std::printf("%-38s %-20s %s\n", r.name,
                        producer.count(r.name) ? producer[r.name]->fn_name : "(not yet measured)",
                        r.what);
        return 0;
    }

    // The selected measurements, plus those producing their rows' peers (a
    // ratio is only ever taken against a peer measured in the same run).
    std::set<const Measurement*> selected;
    for (const RowInfo& r : catalog()) {
        if (!wanted(r.name) || !producer.count(r.name)) continue;
        selected.insert(producer[r.name]);
        if (r.peer && producer.count(r.peer)) selected.insert(producer[r.peer]);
    }

    if (!cli.opt.samples_dir.empty() && mkdir(cli.opt.samples_dir.c_str(), 0755) != 0 &&
        errno != EEXIST) {
        std::fprintf(stderr, "chimera-bench: cannot create %s: %s\n", cli.opt.samples_dir.c_str(),
                     std::strerror(errno));
        return 2;
    }
    cpu_set_t home;
    sched_getaffinity(0, sizeof home, &home);
    watchdog_init();

    std::vector<Measured> measured;
    std::map<std::string, std::string> failed;
    int n = 0, failures = 0;
    const int total = int(selected.size());
    const std::uint64_t t_start = mono_ns();
    for (const Measurement* m : all) {
        if (!selected.count(m)) continue;
        std::fprintf(stderr, "chimera-bench: [%2d/%d] %-28s", ++n, total, m->fn_name);
        std::fflush(nullptr);  // no buffered output may be duplicated by a fork
        const std::uint64_t t0 = mono_ns();
        const std::size_t before = measured.size();
        Session s(cli.opt, &measured);
        watchdog_arm(cli.opt.watchdog_s);
        std::string outcome = "ok";
        try {
            m->fn(s);
        } catch (const Skip& e) {
            outcome = std::string("skipped: ") + e.what();
            for (const std::string& r : m->rows) s.skip(r, e.what());
        } catch (const std::exception& e) {
            outcome = std::string("FAILED: ") + e.what();
            ++failures;
            for (const std::string& r : m->rows) failed[r] = e.what();
        }
        watchdog_disarm();
        sched_setaffinity(0, sizeof home, &home);
        // A row must come from the measurement that declares it, once.
        for (std::size_t i = before; i < measured.size(); ++i) {
            const auto& rows = m->rows;
            if (std::find(rows.begin(), rows.end(), measured[i].name) == rows.end()) {
                std::fprintf(stderr, "\nchimera-bench: %s emitted undeclared row %s\n", m->fn_name,
                             measured[i].name.c_str());
                return 3;
            }
        }
        std::fprintf(stderr, " %6.2f s  %s\n", double(mono_ns() - t0) / 1e9, outcome.c_str());
    }

    // Join with the catalog, in catalog order. A row measured twice (skipped
    // after a partial emit) keeps its first figure.
    std::map<std::string, const Measured*> by_name;
    for (const Measured& x : measured) by_name.emplace(x.name, &x);
    std::vector<Row> rows;
    std::vector<Unmeasured> rest;
    for (const RowInfo& info : catalog()) {
        auto it = by_name.find(info.name);
        const bool have = it != by_name.end() && it->second->skipped.empty();
        if (!have) {
            if (!wanted(info.name)) continue;
            if (failed.count(info.name)) rest.push_back({&info, "failed: " + failed[info.name]});
            else if (it != by_name.end()) rest.push_back({&info, "skipped: " + it->second->skipped});
            else if (!producer.count(info.name)) rest.push_back({&info, "not yet measured"});
            continue;
        }
        Row row{&info, *it->second};
        if (info.peer) {
            auto p = by_name.find(info.peer);
            if (p != by_name.end() && p->second->skipped.empty()) row.peer_value = p->second->value;
            if (std::isfinite(row.peer_value) && row.peer_value != 0 && std::isfinite(row.m.value))
                row.ratio = row.m.value / row.peer_value;
        }
        const Target& t = info.target;
        const double v = row.m.value;
        switch (t.kind) {
        case Target::kNone: break;
        case Target::kRatioAtMost:
            if (std::isfinite(row.ratio)) row.target_met = row.ratio <= t.bound;
            break;
        case Target::kValueAtMost:
            if (std::isfinite(v)) row.target_met = v <= t.bound;
            break;
        case Target::kValueBelow:
            if (std::isfinite(v)) row.target_met = v < t.bound;
            break;
        case Target::kValueAtLeast:
            if (std::isfinite(v)) row.target_met = v >= t.bound;
            break;
        }
        rows.push_back(row);
    }

    std::printf("chimera-bench%s: %zu rows measured in %.1f s\n\n", cli.opt.quick ? " --quick" : "",
                rows.size(), double(mono_ns() - t_start) / 1e9);
    print_table(stdout, rows, rest);
    std::fflush(stdout);
    try {
        if (!cli.json.empty()) write_rows_json(cli.json, rows);
        if (!cli.unmeasured_json.empty()) write_unmeasured_json(cli.unmeasured_json, rest);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "chimera-bench: %s\n", e.what());
        return 1;
    }
    if (failures) std::fprintf(stderr, "chimera-bench: %d measurement(s) failed\n", failures);
    return failures ? 1 : 0;
}

}  // namespace
}  // namespace chm::bench

int main(int argc, char** argv) {
    // Line-buffered even into a pipe, so bench/run.py shows progress live.
    std::setvbuf(stdout, nullptr, _IOLBF, 0);
    return chm::bench::run(chm::bench::parse(argc, argv));
}
