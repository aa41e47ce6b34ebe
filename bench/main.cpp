// chimera-bench: runs the registered measurements (every peer and every
// Chimera row that exists), joins their figures with the catalog, prints the
// table and writes the JSON that bench/run.py turns into docs/benchmarks.md.
//
//   chimera-bench [--quick] [--filter REGEX] [--json FILE]
//                 [--unmeasured-json FILE] [--samples DIR] [--cpus A,B] [--list]
//                 [--rounds N]
//
// Robust, not lucky: every row with a target, and its peer, is measured in
// --rounds interleaved rounds (round 1 is the whole selection; rounds 2..N
// repeat only the target rows' measurements and their peers', each peer's
// right after the first row that needs it), and a target is met only when
// it held in every round. The row's figure is the median of its rounds'.
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
    int rounds = 3;  // rounds of every target row and its peer
};

[[noreturn]] void usage(int code) {
    std::fprintf(code ? stderr : stdout,
                 "usage: chimera-bench [--quick] [--filter REGEX] [--json FILE]\n"
                 "                     [--unmeasured-json FILE] [--samples DIR] [--cpus A,B] [--list]\n"
                 "                     [--rounds N]\n"
                 "  --quick            few short runs (whole suite well under a minute)\n"
                 "  --filter REGEX     only measurements producing a matching row (and their peers)\n"
                 "  --json FILE        write the measured rows as a JSON array\n"
                 "  --unmeasured-json FILE  catalog rows without a figure, with the reason\n"
                 "  --samples DIR      raw samples of distribution rows, one file per row\n"
                 "  --cpus A,B         the two CPUs to use (default: the first two allowed)\n"
                 "  --list             list the catalog and which rows can be measured\n"
                 "  --rounds N         measure every target row and its peer in N interleaved\n"
                 "                     rounds (default 3); a target is met only in every round\n");
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
        else if (a == "--rounds") {
            cli.rounds = std::atoi(value().c_str());
            if (cli.rounds < 1) usage(2);
        }
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

    // The target group: measurements producing a selected row with a
    // target, and those producing such rows' peers. They run in every round.
    std::set<const Measurement*> targeted;
    for (const RowInfo& r : catalog()) {
        if (r.target.kind == Target::kNone || !wanted(r.name) || !producer.count(r.name)) continue;
        targeted.insert(producer[r.name]);
        if (r.peer && producer.count(r.peer)) targeted.insert(producer[r.peer]);
    }
    // A round's order: catalog order, each measurement followed at once by
    // those producing its rows' peers, so a row and its peer are measured
    // close together in every round.
    auto order = [&](const std::set<const Measurement*>& set) {
        std::vector<const Measurement*> seq;
        std::set<const Measurement*> done;
        for (const Measurement* m : all) {
            if (!set.count(m) || done.count(m)) continue;
            seq.push_back(m);
            done.insert(m);
            for (const std::string& r : m->rows) {
                const RowInfo* info = find_row(r);
                if (!info || !info->peer || !producer.count(info->peer)) continue;
                const Measurement* p = producer[info->peer];
                if (set.count(p) && !done.count(p)) {
                    seq.push_back(p);
                    done.insert(p);
                }
            }
        }
        return seq;
    };
    std::vector<std::vector<const Measurement*>> plan{order(selected)};
    for (int r = 1; r < cli.rounds && !targeted.empty(); ++r) plan.push_back(order(targeted));
    int total = 0;
    for (const auto& round : plan) total += int(round.size());

    std::vector<Measured> measured;
    std::map<std::string, std::string> failed;
    int n = 0, failures = 0;
    const std::uint64_t t_start = mono_ns();
    for (std::size_t round = 0; round < plan.size(); ++round) {
        if (plan.size() > 1)
            std::fprintf(stderr, "chimera-bench: round %zu of %zu%s\n", round + 1, plan.size(),
                         round ? " (target rows and their peers)" : "");
        for (const Measurement* m : plan[round]) {
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
                for (const std::string& r : m->rows)
                    failed[r] = e.what() + (round ? " (round " + std::to_string(round + 1) + ")"
                                                  : std::string());
            }
            watchdog_disarm();
            sched_setaffinity(0, sizeof home, &home);
            // A row must come from the measurement that declares it, once.
            for (std::size_t i = before; i < measured.size(); ++i) {
                measured[i].round = int(round);
                const auto& rows = m->rows;
                if (std::find(rows.begin(), rows.end(), measured[i].name) == rows.end()) {
                    std::fprintf(stderr, "\nchimera-bench: %s emitted undeclared row %s\n",
                                 m->fn_name, measured[i].name.c_str());
                    return 3;
                }
            }
            std::fprintf(stderr, " %6.2f s  %s\n", double(mono_ns() - t0) / 1e9, outcome.c_str());
        }
    }

    // Join with the catalog, in catalog order. Per row and round the first
    // figure counts (a row skipped after a partial emit keeps its figure).
    std::map<std::string, std::map<int, const Measured*>> by_name;
    std::map<std::string, const Measured*> skipped;
    for (const Measured& x : measured) {
        if (!x.skipped.empty()) {
            skipped.emplace(x.name, &x);
            continue;
        }
        by_name[x.name].emplace(x.round, &x);
    }
    auto median = [](std::vector<double> v) {
        std::sort(v.begin(), v.end());
        if (v.empty()) return kNull;
        const std::size_t h = v.size() / 2;
        return v.size() % 2 ? v[h] : (v[h - 1] + v[h]) / 2;
    };
    auto judge = [](const Target& t, double v, double ratio, double peer) -> int {
        switch (t.kind) {
        case Target::kNone: return -1;
        case Target::kRatioPlusAtMost:
            return std::isfinite(v) && std::isfinite(peer) ? v <= t.bound * peer + t.plus : -1;
        case Target::kRatioAtMost: return std::isfinite(ratio) ? ratio <= t.bound : -1;
        case Target::kValueAtMost: return std::isfinite(v) ? v <= t.bound : -1;
        case Target::kValueBelow: return std::isfinite(v) ? v < t.bound : -1;
        case Target::kValueAtLeast: return std::isfinite(v) ? v >= t.bound : -1;
        }
        return -1;
    };
    std::vector<Row> rows;
    std::vector<Unmeasured> rest;
    for (const RowInfo& info : catalog()) {
        auto it = by_name.find(info.name);
        if (it == by_name.end()) {
            if (!wanted(info.name)) continue;
            if (failed.count(info.name)) rest.push_back({&info, "failed: " + failed[info.name]});
            else if (skipped.count(info.name))
                rest.push_back({&info, "skipped: " + skipped[info.name]->skipped});
            else if (!producer.count(info.name)) rest.push_back({&info, "not yet measured"});
            continue;
        }
        const auto& per_round = it->second;
        Row row{&info, *per_round.begin()->second, kNull, kNull, -1, {}, 1};
        row.rounds_wanted = targeted.count(producer[info.name]) ? int(plan.size()) : 1;
        const std::map<int, const Measured*>* peer_rounds = nullptr;
        if (info.peer) {
            auto p = by_name.find(info.peer);
            if (p != by_name.end()) peer_rounds = &p->second;
        }
        std::vector<double> values, peer_values;
        for (const auto& [r, x] : per_round) {
            RoundFigure f;
            f.round = r + 1;
            f.value = x->value;
            f.config = x->config;
            values.push_back(x->value);
            if (peer_rounds) {
                // The peer's figure of the same round (a peer measured in
                // round 1 only serves every round of a row without a target).
                auto q = peer_rounds->find(r);
                if (q == peer_rounds->end() && row.rounds_wanted == 1) q = peer_rounds->begin();
                if (q != peer_rounds->end()) f.peer_value = q->second->value;
            }
            if (std::isfinite(f.peer_value) && f.peer_value != 0 && std::isfinite(f.value))
                f.ratio = f.value / f.peer_value;
            f.met = judge(info.target, f.value, f.ratio, f.peer_value);
            row.rounds.push_back(f);
        }
        if (peer_rounds)
            for (const auto& [r, x] : *peer_rounds)
                if (row.rounds_wanted > 1 || r == peer_rounds->begin()->first)
                    peer_values.push_back(x->value);
        row.m.value = median(values);
        for (const auto& [r, x] : per_round) {
            if (std::isfinite(x->min)) row.m.min = std::isfinite(row.m.min) ? std::min(row.m.min, x->min) : x->min;
            if (std::isfinite(x->max)) row.m.max = std::isfinite(row.m.max) ? std::max(row.m.max, x->max) : x->max;
        }
        if (row.rounds.size() > 1) {
            // The rounds' own figures, after the first round's description.
            std::string rv;
            for (const RoundFigure& f : row.rounds) {
                char b[48];
                std::snprintf(b, sizeof b, "%s%.4g", rv.empty() ? "" : ", ", f.value);
                rv += b;
            }
            row.m.config += "; round 1 described; value = median of " +
                            std::to_string(row.rounds.size()) + " rounds (" + rv + ")";
        }
        row.peer_value = median(peer_values);
        if (std::isfinite(row.peer_value) && row.peer_value != 0 && std::isfinite(row.m.value))
            row.ratio = row.m.value / row.peer_value;
        if (info.target.kind != Target::kNone) {
            // Met only when it held in every round the run asked for.
            bool all = int(row.rounds.size()) >= row.rounds_wanted, any_figure = false;
            for (const RoundFigure& f : row.rounds) {
                if (f.met < 0) all = false;
                else any_figure = true;
                if (f.met == 0) all = false;
            }
            row.target_met = any_figure ? int(all) : -1;
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
