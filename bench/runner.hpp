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

// A measured row joined with its catalog entry and its peer's figure.
struct Row {
    const RowInfo* info;
    Measured m;
    double peer_value = kNull;
    double ratio = kNull;  // value / peer_value
    int target_met = -1;   // -1: no target or no figure to judge it by
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
