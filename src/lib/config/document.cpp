// Configuration documents: parsing, key paths, messages, key listing
// (chimera/config.h).
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <vector>

#include "chimera/err.h"
#include "config.hpp"

namespace chm::config {

namespace {

thread_local char t_error[1024];

constexpr std::size_t kMaxFile = 16u << 20;

const char* type_name(toml::node_type t) {
    switch (t) {
    case toml::node_type::table: return "table";
    case toml::node_type::array: return "array";
    case toml::node_type::string: return "string";
    case toml::node_type::integer: return "integer";
    case toml::node_type::floating_point: return "float";
    case toml::node_type::boolean: return "boolean";
    case toml::node_type::date: return "date";
    case toml::node_type::time: return "time";
    case toml::node_type::date_time: return "date-time";
    default: return "nothing";
    }
}

// A string as messages quote it: escaped, at most 40 bytes of it.
std::string quote(std::string_view s) {
    std::string q = "\"";
    for (std::size_t i = 0; i < s.size(); ++i) {
        if (i == 40) {
            q += "...";
            break;
        }
        const unsigned char c = static_cast<unsigned char>(s[i]);
        if (c == '"' || c == '\\') {
            q += '\\';
            q += static_cast<char>(c);
        } else if (c < 0x20 || c == 0x7f) {
            char hex[8];
            std::snprintf(hex, sizeof hex, "\\x%02x", c);
            q += hex;
        } else {
            q += static_cast<char>(c);
        }
    }
    return q + "\"";
}

// The same in single quotes, as messages name keys.
std::string squote(std::string_view s) {
    std::string q = quote(s);
    q.front() = q.back() = '\'';
    return q;
}

// One step of a key path, and where it ends in the path text.
struct Step {
    bool is_index;
    std::string key;
    std::size_t index;
    std::size_t end;
};

bool bare_char(char c) {
    return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_' ||
           c == '-';
}

// Splits a path ("a.b[2].\"c.d\"") into steps; false when malformed.
bool split_path(std::string_view p, std::vector<Step>* steps) {
    std::size_t i = 0;
    if (p.empty()) return true;
    for (;;) {
        Step s{false, {}, 0, 0};
        if (i < p.size() && p[i] == '"') {
            const std::size_t close = p.find('"', i + 1);
            if (close == std::string_view::npos) return false;
            s.key = std::string(p.substr(i + 1, close - i - 1));
            i = close + 1;
        } else {
            const std::size_t start = i;
            while (i < p.size() && bare_char(p[i])) ++i;
            if (i == start) return false;
            s.key = std::string(p.substr(start, i - start));
        }
        s.end = i;
        steps->push_back(std::move(s));
        while (i < p.size() && p[i] == '[') {
            std::size_t v = 0, digits = 0;
            for (++i; i < p.size() && p[i] >= '0' && p[i] <= '9'; ++i, ++digits) {
                if (v > (SIZE_MAX - 9) / 10) return false;
                v = v * 10 + static_cast<std::size_t>(p[i] - '0');
            }
            if (!digits || i >= p.size() || p[i] != ']') return false;
            ++i;
            steps->push_back(Step{true, {}, v, i});
        }
        if (i == p.size()) return true;
        if (p[i] != '.') return false;
        ++i;
    }
}

// What a container is called in messages: "the root table", "table 'arm'".
std::string container_name(const toml::node* n, const std::string& path) {
    if (path.empty()) return "the root table";
    return std::string(n->is_array() ? "array '" : "table '") + path + "'";
}

// A table's keys in document order (toml++ keeps them sorted by name).
std::vector<const toml::key*> keys_in_order(const toml::table& t) {
    std::vector<const toml::key*> keys;
    for (auto&& [k, v] : t) {
        (void)v;
        keys.push_back(&k);
    }
    std::stable_sort(keys.begin(), keys.end(), [](const toml::key* a, const toml::key* b) {
        const auto& x = a->source().begin;
        const auto& y = b->source().begin;
        return x.line != y.line ? x.line < y.line : x.column < y.column;
    });
    return keys;
}

std::size_t edit_distance(std::string_view a, std::string_view b) {
    std::vector<std::size_t> row(b.size() + 1);
    for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
    for (std::size_t i = 1; i <= a.size(); ++i) {
        std::size_t diag = row[0];
        row[0] = i;
        for (std::size_t j = 1; j <= b.size(); ++j) {
            const std::size_t up = row[j];
            row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (a[i - 1] != b[j - 1])});
            diag = up;
        }
    }
    return row[b.size()];
}

// Looks up a container (table or array) for count/key/check_keys: 0 with
// *t == nullptr when absent.
int find_table(const chm_config* cfg, const char* path, const toml::table** t) {
    Found f;
    if (int rc = lookup(cfg, path, &f)) return rc;
    *t = nullptr;
    if (!f.node) return 0;
    if (!f.node->is_table()) return wrong(cfg, path, f.node, "a table");
    *t = f.node->as_table();
    return 0;
}

int parse_into(std::string_view text, std::string name, chm_config_t** out) {
    auto cfg = std::make_unique<chm_config>();
    cfg->name = std::move(name);
    toml::parse_result r = toml::parse(text, std::string_view(cfg->name));
    if (!r) {
        const toml::parse_error& e = r.error();
        const auto& at = e.source().begin;
        return failf(-EBADMSG, "%s:%u:%u: %.*s", cfg->name.c_str(), at.line ? at.line : 1u,
                     at.column ? at.column : 1u, static_cast<int>(e.description().size()),
                     e.description().data());
    }
    cfg->root = std::move(r).table();
    *out = cfg.release();
    return 0;
}

}  // namespace

int fail(int status, const char* msg) noexcept {
    std::snprintf(t_error, sizeof t_error, "%s", msg);
    chm_err_set_last("%s", t_error);  // chm_err_last
    return status;
}

int fail(int status, const std::string& msg) noexcept { return fail(status, msg.c_str()); }

int failf(int status, const char* fmt, ...) noexcept {
    va_list ap;
    va_start(ap, fmt);
    std::vsnprintf(t_error, sizeof t_error, fmt, ap);
    va_end(ap);
    chm_err_set_last("%s", t_error);  // chm_err_last
    return status;
}

std::string where(const chm_config* cfg, const toml::node* n) {
    const auto& at = n->source().begin;
    return cfg->name + ":" + std::to_string(at.line ? at.line : 1u) + ":" +
           std::to_string(at.column ? at.column : 1u);
}

std::string num(double v) {
    char buf[40];
    std::snprintf(buf, sizeof buf, "%.15g", v);
    if (std::strtod(buf, nullptr) != v && !std::isnan(v)) std::snprintf(buf, sizeof buf, "%.17g", v);
    return buf;
}

std::string describe(const toml::node* n) {
    if (!n) return "nothing";
    if (auto* s = n->as_string()) return "string " + quote(s->get());
    if (auto* i = n->as_integer()) return "integer " + std::to_string(i->get());
    if (auto* d = n->as_floating_point()) return "float " + num(d->get());
    if (auto* b = n->as_boolean()) return b->get() ? "boolean true" : "boolean false";
    if (auto* a = n->as_array()) return "an array of " + std::to_string(a->size());
    if (n->is_table()) return "a table";
    return std::string("a ") + type_name(n->type());
}

int lookup(const chm_config* cfg, const char* key, Found* f) {
    if (!cfg || !key) return fail(-EINVAL, "NULL document or key");
    std::vector<Step> steps;
    const std::string_view path(key);
    if (!split_path(path, &steps))
        return failf(-EINVAL, "malformed key path '%s' (keys like a.b[2].\"c.d\")", key);
    const toml::node* cur = &cfg->root;
    std::size_t done = 0;  // path text followed so far
    for (const Step& s : steps) {
        const std::string so_far(path.substr(0, done));
        if (s.is_index) {
            const toml::array* a = cur->as_array();
            if (!a) return wrong(cfg, so_far.c_str(), cur, "an array", "on the way to " + std::string(key));
            if (s.index >= a->size()) {
                f->holder = cur;
                f->holder_path = so_far;
                f->missing = "[" + std::to_string(s.index) + "]";
                return 0;
            }
            cur = a->get(s.index);
        } else {
            const toml::table* t = cur->as_table();
            if (!t) return wrong(cfg, so_far.c_str(), cur, "a table", "on the way to " + std::string(key));
            const toml::node* next = t->get(s.key);
            if (!next) {
                f->holder = cur;
                f->holder_path = so_far;
                f->missing = squote(s.key);
                return 0;
            }
            cur = next;
        }
        done = s.end;
    }
    f->node = cur;
    return 0;
}

int absent(const chm_config* cfg, const char* key, const Found& f, const std::string& expected) {
    const bool index = !f.missing.empty() && f.missing[0] == '[';
    std::string why = container_name(f.holder, f.holder_path);
    if (index)
        why += " has " + std::to_string(f.holder->as_array()->size()) + " elements";
    else
        why += " has no key " + f.missing;
    return fail(-ENOENT, where(cfg, f.holder) + ": " + key + ": expected " + expected +
                             ", got nothing (" + why + ")");
}

int wrong(const chm_config* cfg, const char* key, const toml::node* n, const std::string& expected,
          const std::string& why) {
    std::string m = where(cfg, n) + ": " + (*key ? key : "(root)") + ": expected " + expected +
                    ", got " + describe(n);
    if (!why.empty()) m += " (" + why + ")";
    return fail(-EBADMSG, m);
}

}  // namespace chm::config

using namespace chm::config;

extern "C" {

int chm_config_parse(const char* text, size_t len, const char* name, chm_config_t** out) {
    return guarded([&] {
        if (!text || !out) return fail(-EINVAL, "chm_config_parse: NULL text or out");
        return parse_into(std::string_view(text, len), name ? name : "<string>", out);
    });
}

int chm_config_open(const char* path, chm_config_t** out) {
    return guarded([&] {
        if (!path || !out) return fail(-EINVAL, "chm_config_open: NULL path or out");
        const int fd = ::open(path, O_RDONLY | O_CLOEXEC);
        if (fd < 0) {
            const int e = errno;
            return failf(-e, "%s: cannot open: %s", path, std::strerror(e));
        }
        struct stat st;
        if (::fstat(fd, &st) == 0 && S_ISDIR(st.st_mode)) {
            ::close(fd);
            return failf(-EISDIR, "%s: is a directory, not a configuration file", path);
        }
        std::string text;
        char buf[65536];
        for (;;) {
            const ssize_t k = ::read(fd, buf, sizeof buf);
            if (k < 0 && errno == EINTR) continue;
            if (k < 0) {
                const int e = errno;
                ::close(fd);
                return failf(-e, "%s: cannot read: %s", path, std::strerror(e));
            }
            if (k == 0) break;
            if (text.size() + static_cast<std::size_t>(k) > kMaxFile) {
                ::close(fd);
                return failf(-EFBIG, "%s: larger than %zu MiB", path, kMaxFile >> 20);
            }
            text.append(buf, static_cast<std::size_t>(k));
        }
        ::close(fd);
        return parse_into(text, path, out);
    });
}

void chm_config_close(chm_config_t* cfg) { delete cfg; }

const char* chm_config_name(const chm_config_t* cfg) { return cfg ? cfg->name.c_str() : ""; }

const char* chm_config_last_error(void) { return t_error; }

int chm_config_type(const chm_config_t* cfg, const char* key) {
    return guarded([&] {
        Found f;
        if (int rc = lookup(cfg, key, &f)) return rc;
        if (!f.node) return static_cast<int>(CHM_CONFIG_NONE);
        switch (f.node->type()) {
        case toml::node_type::table: return static_cast<int>(CHM_CONFIG_TABLE);
        case toml::node_type::array: return static_cast<int>(CHM_CONFIG_ARRAY);
        case toml::node_type::string: return static_cast<int>(CHM_CONFIG_STRING);
        case toml::node_type::integer: return static_cast<int>(CHM_CONFIG_INTEGER);
        case toml::node_type::floating_point: return static_cast<int>(CHM_CONFIG_FLOAT);
        case toml::node_type::boolean: return static_cast<int>(CHM_CONFIG_BOOL);
        default: return static_cast<int>(CHM_CONFIG_DATETIME);
        }
    });
}

int chm_config_count(const chm_config_t* cfg, const char* key, size_t* n) {
    return guarded([&] {
        if (!n) return fail(-EINVAL, "chm_config_count: NULL n");
        Found f;
        if (int rc = lookup(cfg, key, &f)) return rc;
        if (!f.node) {
            *n = 0;
        } else if (auto* a = f.node->as_array()) {
            *n = a->size();
        } else if (auto* t = f.node->as_table()) {
            *n = t->size();
        } else {
            return wrong(cfg, key, f.node, "an array or a table");
        }
        return 0;
    });
}

int chm_config_key(const chm_config_t* cfg, const char* table, size_t index, char* buf, size_t len) {
    return guarded([&] {
        if (!buf || !len) return fail(-EINVAL, "chm_config_key: NULL buf or len 0");
        const toml::table* t = nullptr;
        if (int rc = find_table(cfg, table, &t)) return rc;
        if (!t || index >= t->size())
            return failf(-ENOENT, "%s: %s has no key number %zu", cfg->name.c_str(),
                         *table ? table : "the root table", index);
        const toml::key* k = keys_in_order(*t)[index];
        if (k->str().size() >= len) {
            const auto& at = k->source().begin;
            return failf(-ENAMETOOLONG, "%s:%u:%u: key %s is longer than %zu bytes", cfg->name.c_str(),
                         at.line, at.column, squote(k->str()).c_str(), len - 1);
        }
        std::memcpy(buf, k->str().data(), k->str().size());
        buf[k->str().size()] = '\0';
        return 0;
    });
}

int chm_config_check_keys(const chm_config_t* cfg, const char* table, const char* const* allowed,
                          size_t n) {
    return guarded([&] {
        if (n && !allowed) return fail(-EINVAL, "chm_config_check_keys: NULL allowed");
        for (size_t i = 0; i < n; ++i)
            if (!allowed[i]) return fail(-EINVAL, "chm_config_check_keys: NULL allowed name");
        const toml::table* t = nullptr;
        if (int rc = find_table(cfg, table, &t)) return rc;
        if (!t) return 0;
        for (const toml::key* k : keys_in_order(*t)) {
            const std::string_view name = k->str();
            std::size_t best = SIZE_MAX, best_i = 0;
            for (size_t i = 0; i < n; ++i) {
                if (name == allowed[i]) {
                    best = 0;
                    break;
                }
                const std::size_t d = edit_distance(name, allowed[i]);
                if (d < best) best = d, best_i = i;
            }
            if (best == 0) continue;
            const auto& at = k->source().begin;
            std::string m = cfg->name + ":" + std::to_string(at.line) + ":" + std::to_string(at.column) +
                            ": unknown key " + squote(name);
            m += " in " + container_name(t, table);
            if (n && best <= 2 && best < name.size())
                m += std::string(" (did you mean '") + allowed[best_i] + "'?)";
            else if (n) {
                m += " (expected";
                for (size_t i = 0; i < n; ++i) m += std::string(i ? ", " : " ") + allowed[i];
                m += ")";
            } else {
                m += " (it takes no keys)";
            }
            return fail(-EBADMSG, m);
        }
        return 0;
    });
}

int chm_config_where(const chm_config_t* cfg, const char* key, char* buf, size_t len) {
    return guarded([&] {
        if (!buf || !len) return fail(-EINVAL, "chm_config_where: NULL buf or len 0");
        Found f;
        if (int rc = lookup(cfg, key, &f)) return rc;
        const std::string w = where(cfg, f.node ? f.node : f.holder);
        if (w.size() >= len) return failf(-ENAMETOOLONG, "%s: does not fit in %zu bytes", w.c_str(), len);
        std::memcpy(buf, w.c_str(), w.size() + 1);
        return 0;
    });
}

int chm_config_error(const chm_config_t* cfg, const char* key, const char* fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    const int rc = guarded([&] {
        if (!fmt) return fail(-EINVAL, "chm_config_error: NULL fmt");
        Found f;
        if (int r = lookup(cfg, key, &f)) return r;
        char msg[768];
        std::vsnprintf(msg, sizeof msg, fmt, ap);
        return fail(-EBADMSG, where(cfg, f.node ? f.node : f.holder) + ": " + (*key ? key : "(root)") +
                                  ": " + msg);
    });
    va_end(ap);
    return rc;
}

}  // extern "C"
