// Suite `config`, differential: random documents are generated from a model
// (nested tables, arrays of tables, every value type, quoted keys, escaped
// strings), written as TOML while the line and column of every value and
// table header are recorded, parsed with chimera/config.h and read back.
// Every value must come back equal, every random range check must agree
// with the model, and every error must name the recorded line and column.
#include <gtest/gtest.h>

#include <algorithm>
#include <cerrno>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "chimera/config.h"

namespace {

enum class Kind { Int, Float, Bool, String, Ints, Floats, Table, Tables };

struct Node {
    Kind kind;
    std::int64_t i = 0;
    double f = 0;
    bool b = false;
    std::string s;
    std::vector<std::int64_t> ints;
    std::vector<double> floats;
    std::vector<std::pair<std::string, std::unique_ptr<Node>>> keys;  // Table, in order
    std::vector<std::unique_ptr<Node>> tables;                       // Tables
    int line = 0, column = 0;  // where the value (or the table's header) starts
};

bool scalar(Kind k) { return k != Kind::Table && k != Kind::Tables; }

class Gen {
public:
    explicit Gen(std::uint32_t seed) : rng_(seed) {}

    std::unique_ptr<Node> table(int depth) {
        auto t = std::make_unique<Node>();
        t->kind = Kind::Table;
        const int n = pick(0, 6);
        for (int k = 0; k < n; ++k) {
            std::string key = fresh_key(*t);
            const int r = pick(0, depth < 3 ? 9 : 6);
            std::unique_ptr<Node> v;
            if (r <= 6) {
                v = value(static_cast<Kind>(r % 6));
            } else if (r <= 8) {
                v = table(depth + 1);
            } else {
                v = std::make_unique<Node>();
                v->kind = Kind::Tables;
                for (int e = pick(1, 3); e > 0; --e) v->tables.push_back(table(depth + 1));
            }
            t->keys.emplace_back(std::move(key), std::move(v));
        }
        // TOML puts a table's own values before its sub-tables' headers:
        // this is the order the document will have.
        std::stable_partition(t->keys.begin(), t->keys.end(),
                              [](const auto& kv) { return scalar(kv.second->kind); });
        return t;
    }

    int pick(int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(rng_); }
    std::int64_t any_int() {
        switch (pick(0, 3)) {
        case 0: return pick(-10, 10);
        case 1: return std::uniform_int_distribution<std::int64_t>(-100000, 100000)(rng_);
        default: return std::uniform_int_distribution<std::int64_t>(INT64_MIN, INT64_MAX)(rng_);
        }
    }
    double any_double() {
        if (pick(0, 20) == 0) return pick(0, 1) ? INFINITY : -INFINITY;
        if (pick(0, 2) == 0) return pick(-100, 100) / 4.0;
        return std::ldexp(std::uniform_real_distribution<double>(-1, 1)(rng_), pick(-300, 300));
    }

private:
    std::unique_ptr<Node> value(Kind k) {
        auto v = std::make_unique<Node>();
        v->kind = k;
        switch (k) {
        case Kind::Int: v->i = any_int(); break;
        case Kind::Float: v->f = any_double(); break;
        case Kind::Bool: v->b = pick(0, 1); break;
        case Kind::String:
            for (int n = pick(0, 20); n > 0; --n) {
                const char* special = "\"\\\n\t";
                v->s += pick(0, 5) ? static_cast<char>(pick(0x20, 0x7e)) : special[pick(0, 3)];
            }
            break;
        case Kind::Ints:
            for (int n = pick(0, 6); n > 0; --n) v->ints.push_back(any_int());
            break;
        default:
            for (int n = pick(0, 6); n > 0; --n) v->floats.push_back(any_double());
            break;
        }
        return v;
    }

    std::string fresh_key(const Node& t) {
        static const char* const names[] = {"a", "gain", "rate_hz", "x-1", "K", "deep", "42", "q"};
        for (;;) {
            std::string k = names[pick(0, 7)];
            if (pick(0, 4) == 0) k += pick(0, 1) ? ".dot" : " space";  // needs quoting
            bool used = false;
            for (auto& [name, v] : t.keys) used |= name == k;
            if (!used) return k;
        }
    }

    std::mt19937 rng_;
};

bool bare(const std::string& k) { return k.find_first_of(". ") == std::string::npos; }
std::string key_text(const std::string& k) { return bare(k) ? k : "\"" + k + "\""; }

std::string num_text(double d) {
    if (std::isinf(d)) return d > 0 ? "inf" : "-inf";
    char buf[40];
    std::snprintf(buf, sizeof buf, "%.17g", d);
    std::string s = buf;
    if (s.find_first_of(".e") == std::string::npos) s += ".0";
    return s;
}

// Writes the document, recording where each value and header starts.
class Writer {
public:
    std::string text;

    void table_body(Node& t, const std::string& path) {
        for (auto& [k, v] : t.keys)
            if (scalar(v->kind)) line_value(k, *v);
        for (auto& [k, v] : t.keys) {
            const std::string p = join(path, k);
            if (v->kind == Kind::Table) {
                header("[" + p + "]", *v);
                table_body(*v, p);
            } else if (v->kind == Kind::Tables) {
                for (auto& e : v->tables) {
                    header("[[" + p + "]]", *e);
                    table_body(*e, p);
                }
                v->line = v->tables[0]->line;  // the array starts at its first header
                v->column = 1;
            }
        }
    }

    static std::string join(const std::string& path, const std::string& k) {
        return path.empty() ? key_text(k) : path + "." + key_text(k);
    }

private:
    void header(const std::string& h, Node& t) {
        t.line = line_;
        t.column = 1;
        emit(h + "\n");
    }
    void line_value(const std::string& k, Node& v) {
        const std::string lhs = key_text(k) + " = ";
        v.line = line_;
        v.column = static_cast<int>(lhs.size()) + 1;
        std::string rhs;
        switch (v.kind) {
        case Kind::Int: rhs = std::to_string(v.i); break;
        case Kind::Float: rhs = num_text(v.f); break;
        case Kind::Bool: rhs = v.b ? "true" : "false"; break;
        case Kind::String:
            rhs = "\"";
            for (char c : v.s) rhs += c == '"' ? "\\\"" : c == '\\' ? "\\\\" : c == '\n' ? "\\n" : c == '\t' ? "\\t" : std::string(1, c);
            rhs += "\"";
            break;
        case Kind::Ints:
            for (std::size_t i = 0; i < v.ints.size(); ++i) rhs += (i ? ", " : "") + std::to_string(v.ints[i]);
            rhs = "[" + rhs + "]";
            break;
        default:
            for (std::size_t i = 0; i < v.floats.size(); ++i) rhs += (i ? ", " : "") + num_text(v.floats[i]);
            rhs = "[" + rhs + "]";
            break;
        }
        emit(lhs + rhs + "\n");
    }
    void emit(const std::string& s) {
        text += s;
        ++line_;
    }
    int line_ = 1;
};

std::string at(const Node& n) { return "m.toml:" + std::to_string(n.line) + ":" + std::to_string(n.column) + ": "; }
std::string err() { return chm_config_last_error(); }
bool starts(const std::string& s, const std::string& p) { return s.rfind(p, 0) == 0; }

std::size_t g_checked = 0;  // values and tables compared, so a run that checks nothing fails

// Checks everything under table `t` (at `path`) against the parsed document.
void check(chm_config_t* cfg, Gen& g, const Node& t, const std::string& path) {
    const Node root_pos{Kind::Table, 0, 0, false, {}, {}, {}, {}, {}, 1, 1};
    const Node& tpos = path.empty() ? root_pos : t;
    size_t n = 99;
    ASSERT_EQ(chm_config_count(cfg, path.c_str(), &n), 0) << err();
    ASSERT_EQ(n, t.keys.size()) << path;
    // A missing key is reported at the table's own place.
    const std::string missing = Writer::join(path, "zz_missing");
    std::int64_t iv = 0;
    ASSERT_EQ(chm_config_require_int64(cfg, missing.c_str(), 0, 1, &iv), -ENOENT);
    ASSERT_TRUE(starts(err(), at(tpos) + missing + ": expected an integer in [0, 1], got nothing")) << err();
    // check_keys with one allowed name removed names that key.
    if (!t.keys.empty()) {
        std::vector<const char*> allowed;
        const std::size_t drop = static_cast<std::size_t>(g.pick(0, static_cast<int>(t.keys.size()) - 1));
        for (std::size_t i = 0; i < t.keys.size(); ++i)
            if (i != drop) allowed.push_back(t.keys[i].first.c_str());
        ASSERT_EQ(chm_config_check_keys(cfg, path.c_str(), allowed.data(), allowed.size()), -EBADMSG);
        ASSERT_NE(err().find("unknown key '" + t.keys[drop].first + "'"), std::string::npos) << err();
        allowed.push_back(t.keys[drop].first.c_str());
        ASSERT_EQ(chm_config_check_keys(cfg, path.c_str(), allowed.data(), allowed.size()), 0) << err();
    }
    for (std::size_t i = 0; i < t.keys.size(); ++i) {
        const auto& [k, v] = t.keys[i];
        const std::string p = Writer::join(path, k);
        ++g_checked;
        char name[64];
        ASSERT_EQ(chm_config_key(cfg, path.c_str(), i, name, sizeof name), 0) << err();
        ASSERT_EQ(name, k) << "document order in " << path;
        char where[128];
        ASSERT_EQ(chm_config_where(cfg, p.c_str(), where, sizeof where), 0) << err();
        ASSERT_EQ(std::string(where) + ": ", at(*v)) << p;
        switch (v->kind) {
        case Kind::Int: {
            ASSERT_EQ(chm_config_type(cfg, p.c_str()), CHM_CONFIG_INTEGER);
            std::int64_t lo = g.any_int(), hi = g.any_int();
            if (lo > hi) std::swap(lo, hi);
            const bool in = v->i >= lo && v->i <= hi;
            ASSERT_EQ(chm_config_get_int64(cfg, p.c_str(), lo, lo, hi, &iv), in ? 0 : -EBADMSG) << p;
            ASSERT_EQ(chm_config_require_int64(cfg, p.c_str(), INT64_MIN, INT64_MAX, &iv), 0);
            ASSERT_EQ(iv, v->i);
            if (!in) {
                ASSERT_TRUE(starts(err(), at(*v) + p + ": expected an integer")) << err();
            }
            break;
        }
        case Kind::Float: {
            ASSERT_EQ(chm_config_type(cfg, p.c_str()), CHM_CONFIG_FLOAT);
            double lo = g.any_double(), hi = g.any_double(), x = 0;
            if (lo > hi) std::swap(lo, hi);
            const bool in = v->f >= lo && v->f <= hi;
            ASSERT_EQ(chm_config_get_double(cfg, p.c_str(), lo, lo, hi, &x), in ? 0 : -EBADMSG) << p;
            if (!in) {
                ASSERT_TRUE(starts(err(), at(*v) + p + ": expected a number")) << err();
            }
            ASSERT_EQ(chm_config_require_double(cfg, p.c_str(), -INFINITY, INFINITY, &x), 0);
            ASSERT_EQ(x, v->f);
            ASSERT_EQ(chm_config_get_int64(cfg, p.c_str(), 0, INT64_MIN, INT64_MAX, &iv), -EBADMSG);
            break;
        }
        case Kind::Bool: {
            int b = -1;
            ASSERT_EQ(chm_config_require_bool(cfg, p.c_str(), &b), 0);
            ASSERT_EQ(b, v->b ? 1 : 0);
            break;
        }
        case Kind::String: {
            std::vector<char> buf(v->s.size() + 1);
            ASSERT_EQ(chm_config_require_string(cfg, p.c_str(), buf.data(), buf.size()), 0) << err();
            ASSERT_EQ(std::string(buf.data()), v->s);
            ASSERT_EQ(chm_config_get_string(cfg, p.c_str(), "", buf.data(), buf.size() - 1 ? buf.size() - 1 : 1),
                      v->s.empty() ? 0 : -EBADMSG);
            int b = 0;
            ASSERT_EQ(chm_config_get_bool(cfg, p.c_str(), 0, &b), -EBADMSG);
            ASSERT_TRUE(starts(err(), at(*v) + p + ": expected true or false, got string \"")) << err();
            break;
        }
        case Kind::Ints:
        case Kind::Floats: {
            const std::size_t len = v->kind == Kind::Ints ? v->ints.size() : v->floats.size();
            ASSERT_EQ(chm_config_count(cfg, p.c_str(), &n), 0);
            ASSERT_EQ(n, len);
            std::vector<std::int64_t> is(len + 1);
            std::vector<double> ds(len + 1);
            if (v->kind == Kind::Ints) {
                ASSERT_EQ(chm_config_get_int64s(cfg, p.c_str(), INT64_MIN, INT64_MAX, len, len, is.data(), &n), 0);
                for (std::size_t e = 0; e < len; ++e) ASSERT_EQ(is[e], v->ints[e]);
            } else {
                ASSERT_EQ(chm_config_get_doubles(cfg, p.c_str(), -INFINITY, INFINITY, len, len, ds.data(), &n), 0);
                for (std::size_t e = 0; e < len; ++e) ASSERT_EQ(ds[e], v->floats[e]);
                if (len) {
                    ASSERT_EQ(chm_config_get_int64s(cfg, p.c_str(), INT64_MIN, INT64_MAX, 0, len, is.data(), &n),
                              -EBADMSG);
                }
            }
            ASSERT_EQ(chm_config_get_doubles(cfg, p.c_str(), -INFINITY, INFINITY, len + 1, len + 1, ds.data(), &n),
                      -EBADMSG);
            ASSERT_TRUE(starts(err(), at(*v) + p + ": expected an array of")) << err();
            break;
        }
        case Kind::Table:
            ASSERT_EQ(chm_config_type(cfg, p.c_str()), CHM_CONFIG_TABLE);
            check(cfg, g, *v, p);
            break;
        case Kind::Tables:
            ASSERT_EQ(chm_config_count(cfg, p.c_str(), &n), 0);
            ASSERT_EQ(n, v->tables.size());
            for (std::size_t e = 0; e < v->tables.size(); ++e)
                check(cfg, g, *v->tables[e], p + "[" + std::to_string(e) + "]");
            break;
        }
        if (::testing::Test::HasFatalFailure()) return;
    }
}

TEST(ConfigModel, RandomDocumentsReadBackAsWritten) {
    const char* env = std::getenv("CHM_CONFIG_SEED");
    const std::uint32_t base = env ? static_cast<std::uint32_t>(std::strtoul(env, nullptr, 0)) : 1;
    const int docs = 400;
    for (int d = 0; d < docs; ++d) {
        const std::uint32_t seed = base + static_cast<std::uint32_t>(d);
        Gen g(seed);
        std::unique_ptr<Node> root = g.table(0);
        Writer w;
        w.table_body(*root, "");
        chm_config_t* cfg = nullptr;
        ASSERT_EQ(chm_config_parse(w.text.data(), w.text.size(), "m.toml", &cfg), 0)
            << "seed " << seed << ": " << err() << "\n" << w.text;
        check(cfg, g, *root, "");
        chm_config_close(cfg);
        ASSERT_FALSE(HasFatalFailure()) << "seed " << seed << ", document:\n" << w.text;
    }
    std::printf("%d documents, %zu values compared\n", docs, g_checked);
    EXPECT_GT(g_checked, 1000u);
}

}  // namespace
