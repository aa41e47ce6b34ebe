// The catalog: every row the report knows, measured or not yet, with its
// unit, its peer, the Chimera II paper's figure and its performance target.
#pragma once

#include <span>
#include <string_view>

namespace chm::bench {

// A target on the row's ratio (value / peer value) or on its value itself.
// kRatioPlusAtMost: value <= bound x peer value + plus (a fixed allowance
// in the row's unit, for a cost that does not scale with the peer's work).
struct Target {
    enum Kind { kNone, kRatioAtMost, kValueAtMost, kValueBelow, kValueAtLeast, kRatioPlusAtMost } kind = kNone;
    double bound = 0;
    double plus = 0;
};

struct RowInfo {
    const char* name;
    const char* unit;    // "ns" (per operation), "%" or "x"
    const char* peer;    // name of the peer row beside which it is judged, or nullptr
    double paper;        // Chimera II Table 1 in the row's unit, or kNull
    Target target;
    const char* what;    // one line: what exactly one operation is
};

std::span<const RowInfo> catalog();
const RowInfo* find_row(std::string_view name);  // nullptr when unknown
// Position in the catalog (report order); catalog().size() when unknown.
std::size_t row_index(std::string_view name);

}  // namespace chm::bench
