// libFuzzer harness: the configuration-file library (chimera/config.h),
// the parser of files people write by hand. The input is parsed as a TOML
// document; when it parses, every value reachable through the API is
// visited (chm_config_count / chm_config_key) and read with every getter
// under ranges taken from the input. The API must never crash, return a
// status it does not document, accept a value outside the range asked for,
// or give an error message that does not name the document.
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>

#include "chimera/config.h"

namespace {

constexpr int kMaxVisits = 2000;

void expect(bool ok) {
    if (!ok) std::abort();
}

void expect_status(int rc) {
    expect(rc == 0 || rc == -EINVAL || rc == -ENOENT || rc == -EBADMSG || rc == -ENAMETOOLONG);
    if (rc == -EBADMSG || rc == -ENOENT) {
        const char* e = chm_config_last_error();
        expect(std::strncmp(e, "f.toml:", 7) == 0);
    }
}

struct Walk {
    chm_config_t* cfg;
    std::int64_t ilo, ihi;
    double dlo, dhi;
    int visits = 0;

    void value(const std::string& p) {
        const char* k = p.c_str();
        const int type = chm_config_type(cfg, k);
        expect(type >= CHM_CONFIG_NONE && type <= CHM_CONFIG_DATETIME);
        std::int64_t i = 0;
        int rc = chm_config_get_int64(cfg, k, ilo, ilo, ihi, &i);
        expect_status(rc);
        if (rc == 0) expect(i >= ilo && i <= ihi);
        rc = chm_config_require_int64(cfg, k, INT64_MIN, INT64_MAX, &i);
        expect((rc == 0) == (type == CHM_CONFIG_INTEGER));
        double d = 0;
        rc = chm_config_get_double(cfg, k, dlo, dlo, dhi, &d);
        expect_status(rc);
        if (rc == 0) expect(!std::isnan(d) && d >= dlo && d <= dhi);
        int b = 0;
        rc = chm_config_require_bool(cfg, k, &b);
        expect((rc == 0) == (type == CHM_CONFIG_BOOL) && (b == 0 || b == 1));
        char s[24];
        rc = chm_config_get_string(cfg, k, "", s, sizeof s);
        expect_status(rc);
        if (rc == 0) expect(std::strlen(s) < sizeof s);
        const char* const choices[] = {"double", "float", "int32", "a"};
        std::size_t c = 0;
        rc = chm_config_get_choice(cfg, k, choices, 4, 0, &c);
        expect_status(rc);
        expect(c < 4);
        double ds[8];
        std::int64_t is[8];
        std::size_t n = 99;
        rc = chm_config_get_doubles(cfg, k, dlo, dhi, 0, 8, ds, &n);
        expect_status(rc);
        if (rc == 0) {
            expect(n <= 8);
            for (std::size_t e = 0; e < n; ++e) expect(ds[e] >= dlo && ds[e] <= dhi);
        }
        rc = chm_config_get_int64s(cfg, k, ilo, ihi, 0, 8, is, &n);
        expect_status(rc);
        if (rc == 0)
            for (std::size_t e = 0; e < n; ++e) expect(is[e] >= ilo && is[e] <= ihi);
        char at[256];
        expect_status(chm_config_where(cfg, k, at, sizeof at));
        expect_status(chm_config_error(cfg, k, "fuzz %d", 1));
        if (type == CHM_CONFIG_TABLE || type == CHM_CONFIG_ARRAY) children(p, type);
    }

    void children(const std::string& p, int type) {
        std::size_t n = 0;
        expect(chm_config_count(cfg, p.c_str(), &n) == 0);
        const char* const allowed[] = {"name", "type", "rate_hz"};
        if (type == CHM_CONFIG_TABLE) expect_status(chm_config_check_keys(cfg, p.c_str(), allowed, 3));
        for (std::size_t i = 0; i < n && ++visits < kMaxVisits; ++i) {
            if (type == CHM_CONFIG_ARRAY) {
                value(p + "[" + std::to_string(i) + "]");
                continue;
            }
            char key[128];
            const int rc = chm_config_key(cfg, p.c_str(), i, key, sizeof key);
            expect_status(rc);
            if (rc) continue;
            // A key holding a quote cannot be written as a path segment.
            if (std::strchr(key, '"')) continue;
            value(p.empty() ? "\"" + std::string(key) + "\"" : p + ".\"" + key + "\"");
        }
        expect(chm_config_key(cfg, p.c_str(), n, nullptr, 0) == -EINVAL);
    }
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const char* text = reinterpret_cast<const char*>(data);
    chm_config_t* cfg = nullptr;
    const int rc = chm_config_parse(text, size, "f.toml", &cfg);
    expect_status(rc);
    if (rc) {
        expect(cfg == nullptr);
        return 0;
    }
    // Ranges from the first bytes: any order, any magnitude.
    std::int64_t a = 0, b = 0;
    std::memcpy(&a, data, size < 8 ? size : 8);
    if (size > 8) std::memcpy(&b, data + 8, size - 8 < 8 ? size - 8 : 8);
    Walk w{cfg, a < b ? a : b, a < b ? b : a, 0, 0};
    w.dlo = static_cast<double>(w.ilo) / 1e6;
    w.dhi = static_cast<double>(w.ihi) / 1e6;
    w.value("");
    // The document's first line as a key path: malformed paths too.
    const std::string first(text, strnlen(text, size < 200 ? size : 200));
    const std::string path = first.substr(0, first.find('\n'));
    if (chm_config_type(cfg, path.c_str()) >= 0) w.value(path);
    chm_config_close(cfg);
    return 0;
}
