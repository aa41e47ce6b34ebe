// `chimera svar`: the state-variable table of a running system, from the
// operator's terminal, attached as a host process.
//   list                          every variable: type, shape, unit, writer, writes, value
//   get NAME                      one variable's value, every element
//   set NAME V...                 write a set-point (refused while another writer has it)
//   declare NAME TYPE RxC [UNIT]  declare a variable (TYPE: double float int32 uint32 bool)
//   plan CONFIG                   bytes per cycle and per second of a system's modules (plan.cpp)
#include <cerrno>
#include <cinttypes>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "chimera/bp.h"
#include "chimera/svar.h"
#include "cmd.hpp"

namespace chimera_cmd {

namespace {

const char* kTypes[] = {"", "double", "float", "int32", "uint32", "bool"};

std::string element(const chm_svar_info_t& i, const unsigned char* p, std::size_t k) {
    char b[64];
    switch (i.type) {
    case CHM_SVAR_DOUBLE: { double v; std::memcpy(&v, p + 8 * k, 8); std::snprintf(b, sizeof b, "%.6g", v); break; }
    case CHM_SVAR_FLOAT: { float v; std::memcpy(&v, p + 4 * k, 4); std::snprintf(b, sizeof b, "%.6g", double(v)); break; }
    case CHM_SVAR_INT32: { std::int32_t v; std::memcpy(&v, p + 4 * k, 4); std::snprintf(b, sizeof b, "%" PRId32, v); break; }
    case CHM_SVAR_UINT32: { std::uint32_t v; std::memcpy(&v, p + 4 * k, 4); std::snprintf(b, sizeof b, "%" PRIu32, v); break; }
    case CHM_SVAR_BOOL: std::snprintf(b, sizeof b, "%s", p[k] ? "true" : "false"); break;
    }
    return b;
}

// Parse one element of `type` from text into p[k]; false when it is not one.
bool parse_element(chm_svar_type_t type, const char* s, unsigned char* p, std::size_t k) {
    char* end = nullptr;
    errno = 0;
    switch (type) {
    case CHM_SVAR_DOUBLE: { double v = std::strtod(s, &end); std::memcpy(p + 8 * k, &v, 8); break; }
    case CHM_SVAR_FLOAT: { float v = std::strtof(s, &end); std::memcpy(p + 4 * k, &v, 4); break; }
    case CHM_SVAR_INT32: {
        long long v = std::strtoll(s, &end, 0);
        if (v < INT32_MIN || v > INT32_MAX) return false;
        std::int32_t x = std::int32_t(v);
        std::memcpy(p + 4 * k, &x, 4);
        break;
    }
    case CHM_SVAR_UINT32: {
        if (*s == '-') return false;
        unsigned long long v = std::strtoull(s, &end, 0);
        if (v > UINT32_MAX) return false;
        std::uint32_t x = std::uint32_t(v);
        std::memcpy(p + 4 * k, &x, 4);
        break;
    }
    case CHM_SVAR_BOOL:
        if (!std::strcmp(s, "true") || !std::strcmp(s, "1")) p[k] = 1;
        else if (!std::strcmp(s, "false") || !std::strcmp(s, "0")) p[k] = 0;
        else return false;
        return true;
    }
    return end && end != s && !*end && errno == 0;
}

int fail(const char* what) {
    say("%s: %s", what, chm_bp_last_error());
    return 1;
}

int get(const char* name) {
    chm_svar_info_t i;
    if (chm_svar_info(name, &i)) return fail("svar get");
    std::vector<unsigned char> v(i.bytes);
    if (chm_svar_get(name, v.data(), v.size())) return fail("svar get");
    for (std::uint32_t r = 0; r < i.rows; ++r) {
        for (std::uint32_t c = 0; c < i.cols; ++c)
            std::printf("%s%s", c ? " " : "", element(i, v.data(), std::size_t(r) * i.cols + c).c_str());
        std::printf("\n");
    }
    return 0;
}

int set(const char* name, const std::vector<const char*>& values) {
    chm_svar_info_t i;
    if (chm_svar_info(name, &i)) return fail("svar set");
    const std::size_t elems = std::size_t(i.rows) * i.cols;
    if (values.size() != elems) {
        say("svar set %s: %zu values given, the variable has %zu (%ux%u)", name, values.size(), elems, i.rows, i.cols);
        return 2;
    }
    const char* outs[] = {name};
    chm_svar_set_t* s = nullptr;
    if (chm_svar_set_create("chimera-cli", nullptr, 0, outs, 1, &s)) return fail("svar set");
    auto* p = static_cast<unsigned char*>(chm_svar_set_local(s, name));
    for (std::size_t k = 0; k < elems; ++k)
        if (!parse_element(i.type, values[k], p, k)) {
            (void)chm_svar_set_destroy(s);
            say("svar set %s: element %zu \"%s\" is not a %s", name, k, values[k], kTypes[i.type]);
            return 2;
        }
    const int r = chm_svar_set_write(s);
    (void)chm_svar_set_destroy(s);
    return r ? fail("svar set") : 0;
}

int declare(const std::vector<const char*>& a) {
    if (a.size() < 3 || a.size() > 4) {
        say("svar declare wants NAME TYPE RxC [UNIT]");
        return 2;
    }
    chm_svar_decl_t d{a[0], chm_svar_type_t(0), 0, 0, a.size() == 4 ? a[3] : ""};
    for (int t = 1; t <= 5; ++t)
        if (!std::strcmp(a[1], kTypes[t])) d.type = chm_svar_type_t(t);
    unsigned rows = 0, cols = 0;
    char tail = 0;
    if (!d.type || std::sscanf(a[2], "%ux%u%c", &rows, &cols, &tail) != 2) {
        say("svar declare %s: TYPE is double, float, int32, uint32 or bool and the shape RxC (e.g. 6x1), not %s %s",
            a[0], a[1], a[2]);
        return 2;
    }
    d.rows = rows;
    d.cols = cols;
    return chm_svar_declare(&d) ? fail("svar declare") : 0;
}

}  // namespace

int svar_list() {
    const int n = chm_svar_count();
    if (n < 0) return fail("svar list");
    if (n == 0) std::printf("no state variables declared\n");
    else std::printf("%-20s %-7s %-9s %-8s %-16s %10s  %s\n", "name", "type", "shape", "unit", "writer", "writes", "value");
    for (int k = 0; k < n; ++k) {
        chm_svar_info_t i;
        if (chm_svar_info_at(k, &i)) return fail("svar list");
        std::vector<unsigned char> v(i.bytes);
        std::string value;
        if (chm_svar_get(i.name, v.data(), v.size()) == 0) {
            const std::size_t elems = std::size_t(i.rows) * i.cols;
            for (std::size_t e = 0; e < elems && e < 6; ++e) value += (e ? " " : "") + element(i, v.data(), e);
            if (elems > 6) value += " ...";
        } else {
            value = "(unreadable)";
        }
        char shape[24];
        std::snprintf(shape, sizeof shape, "%ux%u", i.rows, i.cols);
        std::printf("%-20s %-7s %-9s %-8s %-16s %10u  %s\n", i.name, kTypes[i.type], shape, i.unit,
                    i.has_writer ? i.writer : "-", i.writes, value.c_str());
    }
    return 0;
}

int cmd_svar(const Options& o, const std::vector<const char*>& args) {
    if (args.empty()) {
        say("svar wants a subcommand: list, get NAME, set NAME V..., declare NAME TYPE RxC [UNIT]");
        return 2;
    }
    const std::string sub = args[0];
    const std::vector<const char*> rest(args.begin() + 1, args.end());
    if (sub != "list" && sub != "get" && sub != "set" && sub != "declare" && sub != "plan") {
        say("svar: unknown subcommand \"%s\" (list, get, set, declare or plan)", sub.c_str());
        return 2;
    }
    if (sub == "plan") {
        if (rest.size() != 1) {
            say("svar plan wants one configuration file");
            return 2;
        }
        return cmd_svar_plan(rest[0]);  // no backplane needed
    }
    if ((sub == "list" && !rest.empty()) || (sub == "get" && rest.size() != 1) || (sub == "set" && rest.size() < 2)) {
        say("svar %s: wrong arguments (svar list | get NAME | set NAME V... | declare NAME TYPE RxC [UNIT])",
            sub.c_str());
        return 2;
    }
    if (!file_fit_to_use(o.backplane)) return 1;
    if (chm_bp_attach_host(o.backplane.c_str(), "chimera-cli", nullptr)) {
        say("cannot attach to %s: %s", o.backplane.c_str(), chm_bp_last_error());
        return 1;
    }
    int r;
    if (sub == "list") r = svar_list();
    else if (sub == "get") r = get(rest[0]);
    else if (sub == "set") r = set(rest[0], std::vector<const char*>(rest.begin() + 1, rest.end()));
    else r = declare(rest);
    (void)chm_bp_leave();
    return r;
}

}  // namespace chimera_cmd
