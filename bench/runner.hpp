// What main.cpp needs from the harness and the report: the watchdog's
// arming and the finished rows' output. Measurement files do not include it.
#pragma once

#include <cstdio>
#include <string>
#include <vector>

#include "catalog.hpp"
#include "harness.hpp"

namespace chm::bench {

void watchdog_init();
void watchdog_arm(double seconds);
void watchdog_disarm();

// One round's figure of a row, its peer's figure in the same round, and
// whether the target held in that round (-1: no target or no figure).
struct RoundFigure {
    int round = 0;
    double value = kNull, peer_value = kNull, ratio = kNull;
    int met = -1;
    std::string config;  // that round's own description (its counts, its pinning)
};

// A measured row joined with its catalog entry and its peer's figure. A row
// with a target (and its peer) is measured in every round of the run; its
// value is the median of the rounds' figures, its min and max span every
// round's, and its target is met only when it held in every round.
struct Row {
    const RowInfo* info;
    Measured m;
    double peer_value = kNull;
    double ratio = kNull;  // value / peer_value
    int target_met = -1;   // -1: no target or no figure to judge it by
    std::vector<RoundFigure> rounds;  // one per round that measured it, in order
    int rounds_wanted = 1;            // rounds the run asked of this row
};

// A catalog row without a figure, and why: "not yet measured" (nothing
// produces it yet), "skipped: <reason>" or "failed: <error>".
struct Unmeasured {
    const RowInfo* info;
    std::string status;
};

void print_table(std::FILE* f, const std::vector<Row>& rows, const std::vector<Unmeasured>& rest);
void write_rows_json(const std::string& path, const std::vector<Row>& rows);
void write_unmeasured_json(const std::string& path, const std::vector<Unmeasured>& rest);

}  // namespace chm::bench
