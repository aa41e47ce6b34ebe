// Typed, range-checked getters of the configuration library
// (chimera/config.h). Each getter follows the key path, then either
// applies the caller's default (absent key), reports the absence
// (require_), or checks the value's type and range.
#include <cmath>
#include <cstring>
#include <limits>

#include "config.hpp"

namespace chm::config {
namespace {

constexpr std::int64_t kI64Min = std::numeric_limits<std::int64_t>::min();
constexpr std::int64_t kI64Max = std::numeric_limits<std::int64_t>::max();

std::string int_expected(std::int64_t lo, std::int64_t hi) {
    if (lo == kI64Min && hi == kI64Max) return "an integer";
    return "an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]";
}

std::string num_expected(double lo, double hi) {
    if (std::isinf(lo) && lo < 0 && std::isinf(hi) && hi > 0) return "a number";
    return "a number in [" + num(lo) + ", " + num(hi) + "]";
}

std::string choice_expected(const char* const* choices, std::size_t n) {
    std::string e = "one of";
    for (std::size_t i = 0; i < n; ++i) e += std::string(i ? ", \"" : " \"") + choices[i] + "\"";
    return e;
}

// An integer read as a double: refused when it would round (beyond 2^53).
bool exact_double(std::int64_t i, double* d) {
    const double x = static_cast<double>(i);
    if (x >= 9223372036854775808.0 || static_cast<std::int64_t>(x) != i) return false;
    *d = x;
    return true;
}

// Checks one value against [lo, hi]; 0 and *out, or the -EBADMSG report.
int check_double(const chm_config* cfg, const char* key, const toml::node* n, double lo, double hi,
                 double* out) {
    double v;
    if (auto* f = n->as_floating_point()) {
        v = f->get();
    } else if (auto* i = n->as_integer()) {
        if (!exact_double(i->get(), &v))
            return wrong(cfg, key, n, num_expected(lo, hi), "not exact as a double");
    } else {
        return wrong(cfg, key, n, num_expected(lo, hi));
    }
    if (std::isnan(v) || v < lo || v > hi) return wrong(cfg, key, n, num_expected(lo, hi));
    *out = v;
    return 0;
}

int check_int(const chm_config* cfg, const char* key, const toml::node* n, std::int64_t lo,
              std::int64_t hi, std::int64_t* out) {
    auto* i = n->as_integer();
    if (!i || i->get() < lo || i->get() > hi) return wrong(cfg, key, n, int_expected(lo, hi));
    *out = i->get();
    return 0;
}

bool bad_bounds(double lo, double hi) { return std::isnan(lo) || std::isnan(hi) || lo > hi; }

// The shared shape of every getter: look up, then default / absent / check.
// `check` returns 0 after storing the value, or a status.
template <typename Check, typename Default>
int get(const chm_config* cfg, const char* key, bool required, const std::string& expected,
        Check&& check, Default&& use_default) {
    Found f;
    if (int rc = lookup(cfg, key, &f)) return rc;
    if (f.node) return check(f.node);
    if (required) return absent(cfg, key, f, expected);
    use_default();
    return 0;
}

int get_bool(const chm_config* cfg, const char* key, bool required, int def, int* out) {
    if (!out || (def != 0 && def != 1)) return fail(-EINVAL, "chm_config_get_bool: NULL out or def not 0/1");
    return get(
        cfg, key, required, "true or false",
        [&](const toml::node* n) {
            auto* b = n->as_boolean();
            if (!b) return wrong(cfg, key, n, "true or false");
            *out = b->get() ? 1 : 0;
            return 0;
        },
        [&] { *out = def; });
}

int get_int(const chm_config* cfg, const char* key, bool required, std::int64_t def, std::int64_t lo,
            std::int64_t hi, std::int64_t* out) {
    if (!out || lo > hi) return fail(-EINVAL, "chm_config_get_int64: NULL out or min > max");
    if (!required && (def < lo || def > hi))
        return failf(-EINVAL, "chm_config_get_int64: %s: default outside [min, max]", key ? key : "");
    return get(
        cfg, key, required, int_expected(lo, hi),
        [&](const toml::node* n) { return check_int(cfg, key, n, lo, hi, out); }, [&] { *out = def; });
}

int get_double(const chm_config* cfg, const char* key, bool required, double def, double lo, double hi,
               double* out) {
    if (!out || bad_bounds(lo, hi)) return fail(-EINVAL, "chm_config_get_double: NULL out or bad bounds");
    if (!required && !(def >= lo && def <= hi))
        return failf(-EINVAL, "chm_config_get_double: %s: default outside [min, max]", key ? key : "");
    return get(
        cfg, key, required, num_expected(lo, hi),
        [&](const toml::node* n) { return check_double(cfg, key, n, lo, hi, out); },
        [&] { *out = def; });
}

int get_string(const chm_config* cfg, const char* key, bool required, const char* def, char* buf,
               std::size_t len) {
    if (!buf || !len) return fail(-EINVAL, "chm_config_get_string: NULL buf or len 0");
    if (!def) def = "";
    const std::size_t def_len = std::strlen(def);
    if (!required && def_len >= len)
        return failf(-EINVAL, "chm_config_get_string: %s: default longer than %zu bytes", key ? key : "",
                     len - 1);
    const std::string expected = "a string of at most " + std::to_string(len - 1) + " bytes";
    return get(
        cfg, key, required, expected,
        [&](const toml::node* n) {
            auto* s = n->as_string();
            if (!s || s->get().size() >= len) return wrong(cfg, key, n, expected);
            const std::string& v = s->get();
            if (v.find('\0') != std::string::npos)
                return wrong(cfg, key, n, expected, "it holds a NUL character");
            std::memcpy(buf, v.c_str(), v.size() + 1);
            return 0;
        },
        [&] { std::memcpy(buf, def, def_len + 1); });
}

int get_choice(const chm_config* cfg, const char* key, bool required, const char* const* choices,
               std::size_t n, std::size_t def, std::size_t* out) {
    if (!out || !choices || !n || (!required && def >= n))
        return fail(-EINVAL, "chm_config_get_choice: NULL out or choices, no choices, or def >= n");
    for (std::size_t i = 0; i < n; ++i)
        if (!choices[i]) return fail(-EINVAL, "chm_config_get_choice: NULL choice");
    const std::string expected = choice_expected(choices, n);
    return get(
        cfg, key, required, expected,
        [&](const toml::node* node) {
            if (auto* s = node->as_string()) {
                for (std::size_t i = 0; i < n; ++i) {
                    if (s->get() == choices[i]) {
                        *out = i;
                        return 0;
                    }
                }
            }
            return wrong(cfg, key, node, expected);
        },
        [&] { *out = def; });
}

// The array getters: T is double or int64_t; `one` checks an element.
template <typename T, typename One>
int get_array(const chm_config* cfg, const char* key, const std::string& what, std::size_t min_n,
              std::size_t max_n, T* out, std::size_t* n, One&& one) {
    if (!out || !n || min_n > max_n) return fail(-EINVAL, "NULL out or n, or min_n > max_n");
    std::string expected = "an array of ";
    expected += min_n == max_n ? std::to_string(min_n) : std::to_string(min_n) + " to " + std::to_string(max_n);
    expected += " " + what;
    Found f;
    if (int rc = lookup(cfg, key, &f)) return rc;
    if (!f.node) {
        if (min_n) return absent(cfg, key, f, expected);
        *n = 0;
        return 0;
    }
    const toml::array* a = f.node->as_array();
    if (!a || a->size() < min_n || a->size() > max_n) return wrong(cfg, key, f.node, expected);
    // Checked in full before anything is stored: no half-written out.
    for (std::size_t i = 0; i < a->size(); ++i) {
        T v;
        const std::string elem = std::string(key) + "[" + std::to_string(i) + "]";
        if (int rc = one(elem.c_str(), a->get(i), &v)) return rc;
    }
    for (std::size_t i = 0; i < a->size(); ++i) {
        const std::string elem = std::string(key) + "[" + std::to_string(i) + "]";
        one(elem.c_str(), a->get(i), &out[i]);
    }
    *n = a->size();
    return 0;
}

}  // namespace
}  // namespace chm::config

using namespace chm::config;

extern "C" {

int chm_config_get_bool(const chm_config_t* cfg, const char* key, int def, int* out) {
    return guarded([&] { return get_bool(cfg, key, false, def, out); });
}

int chm_config_require_bool(const chm_config_t* cfg, const char* key, int* out) {
    return guarded([&] { return get_bool(cfg, key, true, 0, out); });
}

int chm_config_get_int64(const chm_config_t* cfg, const char* key, int64_t def, int64_t min,
                         int64_t max, int64_t* out) {
    return guarded([&] { return get_int(cfg, key, false, def, min, max, out); });
}

int chm_config_require_int64(const chm_config_t* cfg, const char* key, int64_t min, int64_t max,
                             int64_t* out) {
    return guarded([&] { return get_int(cfg, key, true, 0, min, max, out); });
}

int chm_config_get_double(const chm_config_t* cfg, const char* key, double def, double min,
                          double max, double* out) {
    return guarded([&] { return get_double(cfg, key, false, def, min, max, out); });
}

int chm_config_require_double(const chm_config_t* cfg, const char* key, double min, double max,
                              double* out) {
    return guarded([&] { return get_double(cfg, key, true, 0, min, max, out); });
}

int chm_config_get_string(const chm_config_t* cfg, const char* key, const char* def, char* buf,
                          size_t len) {
    return guarded([&] { return get_string(cfg, key, false, def, buf, len); });
}

int chm_config_require_string(const chm_config_t* cfg, const char* key, char* buf, size_t len) {
    return guarded([&] { return get_string(cfg, key, true, nullptr, buf, len); });
}

int chm_config_get_choice(const chm_config_t* cfg, const char* key, const char* const* choices,
                          size_t n, size_t def, size_t* out) {
    return guarded([&] { return get_choice(cfg, key, false, choices, n, def, out); });
}

int chm_config_require_choice(const chm_config_t* cfg, const char* key,
                              const char* const* choices, size_t n, size_t* out) {
    return guarded([&] { return get_choice(cfg, key, true, choices, n, 0, out); });
}

int chm_config_get_doubles(const chm_config_t* cfg, const char* key, double lo, double hi,
                           size_t min_n, size_t max_n, double* out, size_t* n) {
    return guarded([&] {
        if (bad_bounds(lo, hi)) return fail(-EINVAL, "chm_config_get_doubles: bad bounds");
        return get_array(cfg, key, num_expected(lo, hi).replace(0, 8, "numbers"), min_n, max_n, out, n,
                         [&](const char* k, const toml::node* e, double* v) {
                             return check_double(cfg, k, e, lo, hi, v);
                         });
    });
}

int chm_config_get_int64s(const chm_config_t* cfg, const char* key, int64_t lo, int64_t hi,
                          size_t min_n, size_t max_n, int64_t* out, size_t* n) {
    return guarded([&] {
        if (lo > hi) return fail(-EINVAL, "chm_config_get_int64s: min > max");
        return get_array(cfg, key, int_expected(lo, hi).replace(0, 10, "integers"), min_n, max_n, out, n,
                         [&](const char* k, const toml::node* e, int64_t* v) {
                             return check_int(cfg, k, e, lo, hi, v);
                         });
    });
}

}  // extern "C"
