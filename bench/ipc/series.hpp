// An experiment's curves as the JSON run.py plots: per named series the
// median, min and max at every x (null where it could not be measured).
#pragma once

#include <cmath>
#include <cstdio>
#include <map>
#include <string>
#include <vector>

#include "../harness.hpp"

namespace chm::bench::ipcb {

struct Series {
    std::vector<double> median, min, max;
    void add(const Stats& s) {
        median.push_back(s.median);
        min.push_back(s.min);
        max.push_back(s.max);
    }
    void add_null() {
        median.push_back(kNull);
        min.push_back(kNull);
        max.push_back(kNull);
    }
};

inline std::string json_list(const std::vector<double>& v) {
    std::string out = "[";
    for (std::size_t i = 0; i < v.size(); ++i) {
        char b[48];
        if (std::isnan(v[i])) std::snprintf(b, sizeof b, "%snull", i ? ", " : "");
        else std::snprintf(b, sizeof b, "%s%.3f", i ? ", " : "", v[i]);
        out += b;
    }
    return out + "]";
}

// {"<x_name>": [...], "unit": "ns", "<group>": {"name": {"median": [...], ...}, ...}}
// plus `extra` (a JSON fragment like "\"note\": \"...\"", or empty).
inline std::string series_json(const std::string& x_name, const std::vector<double>& xs,
                               const std::string& group,
                               const std::vector<std::pair<std::string, Series>>& series,
                               const std::string& extra = "") {
    std::string js = "{\"" + x_name + "\": " + json_list(xs) + ", \"unit\": \"ns\", \"" + group + "\": {";
    for (std::size_t i = 0; i < series.size(); ++i) {
        const Series& s = series[i].second;
        js += (i ? ", \"" : "\"") + series[i].first + "\": {\"median\": " + json_list(s.median) +
              ", \"min\": " + json_list(s.min) + ", \"max\": " + json_list(s.max) + "}";
    }
    js += "}";
    if (!extra.empty()) js += ", " + extra;
    return js + "}\n";
}

}  // namespace chm::bench::ipcb
