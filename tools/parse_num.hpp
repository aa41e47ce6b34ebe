// The tools' one number parser for command-line values (chimera,
// chimera-rtpu): a whole decimal number in [lo, hi], nothing after it.
#pragma once

#include <cerrno>
#include <cstdlib>

namespace chimera_tools {

inline bool parse_num(const char* s, long lo, long hi, long* out) {
    if (!s || !*s) return false;
    char* end = nullptr;
    errno = 0;
    const long v = std::strtol(s, &end, 10);
    if (errno || *end || v < lo || v > hi) return false;
    *out = v;
    return true;
}

// A task id (64 bits, also where long is 32): a whole decimal number >= 0.
inline bool parse_tid(const char* s, long long* out) {
    if (!s || !*s) return false;
    char* end = nullptr;
    errno = 0;
    const long long v = std::strtoll(s, &end, 10);
    if (errno || *end || v < 0) return false;
    *out = v;
    return true;
}

}  // namespace chimera_tools
