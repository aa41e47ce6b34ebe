// Output of a finished run: the human table on stdout and the JSON files
// bench/run.py turns into docs/benchmarks.md. JSON is written by hand (no
// library dependency); a figure that does not exist is null, never a number.
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

#include "runner.hpp"

namespace chm::bench {
namespace {

std::string fmt(const char* f, double v) {
    char buf[64];
    std::snprintf(buf, sizeof buf, f, v);
    return buf;
}

std::string human(double v, const char* unit) {
    if (std::isnan(v)) return "-";
    const std::string u = unit;
    if (u == "ns") {
        const double a = std::fabs(v);
        if (a < 10) return fmt("%.2f ns", v);
        if (a < 1000) return fmt("%.1f ns", v);
        if (a < 1e6) return fmt("%.2f us", v / 1e3);
        return fmt("%.2f ms", v / 1e6);
    }
    if (u == "%") return fmt("%.2f %%", v);
    return fmt("%.3g", v) + u;
}

std::string target_text(const Target& t) {
    switch (t.kind) {
    case Target::kNone: return "";
    case Target::kRatioAtMost: return "ratio <= " + fmt("%g", t.bound);
    case Target::kRatioPlusAtMost: return "ratio <= " + fmt("%g", t.bound) + " +" + fmt("%g", t.plus) + "/peer";
    case Target::kValueAtMost: return "value <= " + fmt("%g", t.bound);
    case Target::kValueBelow: return "value < " + fmt("%g", t.bound);
    case Target::kValueAtLeast: return "value >= " + fmt("%g", t.bound);
    }
    return "";
}

std::string json_string(const std::string& s) {
    std::string o = "\"";
    for (unsigned char c : s) {
        if (c == '"' || c == '\\') {
            o += '\\';
            o += char(c);
        } else if (c < 0x20) {
            char buf[8];
            std::snprintf(buf, sizeof buf, "\\u%04x", unsigned(c));
            o += buf;
        } else {
            o += char(c);
        }
    }
    return o + "\"";
}

std::string json_number(double v) {
    if (!std::isfinite(v)) return "null";
    // Enough digits for ns figures from 0.5 ns to seconds without noise digits.
    return std::fabs(v) >= 1e6 ? fmt("%.0f", v) : fmt("%.6g", v);
}

std::string json_opt(const char* s) { return s ? json_string(s) : "null"; }

std::FILE* open_or_throw(const std::string& path) {
    std::FILE* f = std::fopen(path.c_str(), "w");
    if (!f) throw std::runtime_error("cannot write " + path);
    return f;
}

// Every round's figure of a row: [{"round", "value", "peer_value", "ratio", "met"}].
std::string rounds_json(const Row& r) {
    std::string o = "[";
    for (std::size_t i = 0; i < r.rounds.size(); ++i) {
        const RoundFigure& f = r.rounds[i];
        o += std::string(i ? ", " : "") + "{\"round\": " + std::to_string(f.round) +
             ", \"value\": " + json_number(f.value) + ", \"peer_value\": " +
             json_number(f.peer_value) + ", \"ratio\": " + json_number(f.ratio) + ", \"met\": " +
             (f.met < 0 ? "null" : f.met ? "true" : "false") + ", \"config\": " +
             json_string(f.config) + "}";
    }
    return o + "]";
}

}  // namespace

void print_table(std::FILE* f, const std::vector<Row>& rows, const std::vector<Unmeasured>& rest) {
    std::fprintf(f, "%-37s %11s %23s  %-36s %11s %8s %-14s %10s  %s\n", "row", "value",
                 "min .. max", "peer", "peer value", "ratio", "target", "paper", "config");
    for (const Row& r : rows) {
        const char* unit = r.info->unit;
        const std::string range = std::isnan(r.m.min) && std::isnan(r.m.max)
                                      ? std::string("")
                                      : human(r.m.min, unit) + " .. " + human(r.m.max, unit);
        std::string target = target_text(r.info->target);
        if (r.target_met >= 0) target += r.target_met ? " ok" : " MISS";
        if (r.rounds.size() > 1 && r.target_met >= 0) {
            // Each round's figure judged: the ratio, or the value for a value target.
            const bool by_ratio = r.info->target.kind == Target::kRatioAtMost ||
                                  r.info->target.kind == Target::kRatioPlusAtMost;
            target += " [";
            for (std::size_t i = 0; i < r.rounds.size(); ++i)
                target += (i ? " " : "") + fmt("%.3g", by_ratio ? r.rounds[i].ratio : r.rounds[i].value);
            target += "]";
        }
        std::fprintf(f, "%-37s %11s %23s  %-36s %11s %8s %-14s %10s  %s\n", r.info->name,
                     human(r.m.value, unit).c_str(), range.c_str(),
                     r.info->peer ? r.info->peer : "", human(r.peer_value, unit).c_str(),
                     std::isnan(r.ratio) ? "" : fmt("%.3g", r.ratio).c_str(), target.c_str(),
                     human(r.info->paper, unit).c_str(), r.m.config.c_str());
    }
    std::string pending;
    int n_pending = 0;
    for (const Unmeasured& u : rest) {
        if (u.status == "not yet measured") {
            pending += (n_pending++ % 6 == 0 ? "\n    " : " ") + std::string(u.info->name);
        } else {
            std::fprintf(f, "%-37s %s\n", u.info->name, u.status.c_str());
        }
    }
    if (n_pending)
        std::fprintf(f, "\nnot yet measured (%d rows; their subsystem is not built yet):%s\n",
                     n_pending, pending.c_str());
}

void write_rows_json(const std::string& path, const std::vector<Row>& rows) {
    std::FILE* f = open_or_throw(path);
    std::fprintf(f, "[");
    for (std::size_t i = 0; i < rows.size(); ++i) {
        const Row& r = rows[i];
        const std::string target = target_text(r.info->target);
        std::fprintf(
            f,
            "%s\n  {\"name\": %s, \"unit\": %s, \"value\": %s, \"min\": %s, \"max\": %s, "
            "\"peer\": %s, \"peer_value\": %s, \"ratio\": %s, \"paper_value\": %s, "
            "\"config\": %s, \"target\": %s, \"target_met\": %s, \"what\": %s, "
            "\"rounds_wanted\": %d, \"rounds\": %s}",
            i ? "," : "", json_string(r.info->name).c_str(), json_string(r.info->unit).c_str(),
            json_number(r.m.value).c_str(), json_number(r.m.min).c_str(),
            json_number(r.m.max).c_str(), json_opt(r.info->peer).c_str(),
            json_number(r.peer_value).c_str(), json_number(r.ratio).c_str(),
            json_number(r.info->paper).c_str(), json_string(r.m.config).c_str(),
            target.empty() ? "null" : json_string(target).c_str(),
            r.target_met < 0 ? "null" : (r.target_met ? "true" : "false"),
            json_string(r.info->what).c_str(), r.rounds_wanted, rounds_json(r).c_str());
    }
    std::fprintf(f, "\n]\n");
    if (std::fclose(f) != 0) throw std::runtime_error("cannot write " + path);
}

void write_unmeasured_json(const std::string& path, const std::vector<Unmeasured>& rest) {
    std::FILE* f = open_or_throw(path);
    std::fprintf(f, "[");
    for (std::size_t i = 0; i < rest.size(); ++i) {
        const Unmeasured& u = rest[i];
        const std::string target = target_text(u.info->target);
        std::fprintf(f,
                     "%s\n  {\"name\": %s, \"unit\": %s, \"peer\": %s, \"paper_value\": %s, "
                     "\"target\": %s, \"status\": %s, \"what\": %s}",
                     i ? "," : "", json_string(u.info->name).c_str(),
                     json_string(u.info->unit).c_str(), json_opt(u.info->peer).c_str(),
                     json_number(u.info->paper).c_str(),
                     target.empty() ? "null" : json_string(target).c_str(),
                     json_string(u.status).c_str(), json_string(u.info->what).c_str());
    }
    std::fprintf(f, "\n]\n");
    if (std::fclose(f) != 0) throw std::runtime_error("cannot write " + path);
}

}  // namespace chm::bench
