// A system from its configuration file (chimera/servo.h, "Systems"): the
// state variables to declare and the modules to spawn, on which RTPU, at
// what rate, with which parameters, and which to switch on at start. The
// whole file is read and checked before anything is declared or spawned;
// every error names file:line:column (chimera/config.h).
#include <cerrno>
#include <cstdarg>
#include <climits>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "chimera/bp.h"
#include "chimera/config.h"
#include "chimera/module.h"
#include "chimera/servo.h"
#include "chimera/svar.h"
#include "ipc/err/report.hpp"
#include "kernel/err/last.hpp"

struct chm_servo_system {
    struct Var {
        std::string name, unit;
        chm_svar_type_t type;
        std::uint32_t rows, cols;
    };
    struct Module {
        std::string name, path;
        chm_servo_spawn_t spawn;
        std::vector<std::string> param_names;
        std::vector<const char*> param_ptrs;
        std::vector<double> param_values;
        bool on = false;
        bool spawned = false;
        chm_servo_module_t id{};
    };
    std::string path;
    std::vector<Var> vars;
    std::vector<Module> modules;
    std::uint32_t rtpus = 0;  // bit n: a module runs on RTPU n
};

namespace {

thread_local char t_error[600];

int say(int r, const char* fmt, ...) __attribute__((format(printf, 2, 3)));
int say(int r, const char* fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    std::vsnprintf(t_error, sizeof t_error, fmt, ap);
    va_end(ap);
    chm::kernel::err_last_set(t_error);  // chm_err_last
    return r;
}
int from_config(int r) { return say(r, "%s", chm_config_last_error()); }

const char* const kTypes[] = {"double", "float", "int32", "uint32", "bool"};
const char* const kMiss[] = {"count", "error"};
const char* const kVarKeys[] = {"name", "type", "rows", "cols", "unit"};
const char* const kModuleKeys[] = {"name", "path", "rtpu", "rate_hz", "deadline_ms", "wcet_us", "critical",
                                   "priority", "on_miss", "on", "params"};
const char* const kTopKeys[] = {"svar", "module", "system"};

std::string key(const char* list, std::size_t i, const char* field) {
    return std::string(list) + "[" + std::to_string(i) + "]" + (field ? std::string(".") + field : "");
}

int read_vars(const chm_config_t* c, chm_servo_system* s) {
    std::size_t n = 0;
    if (int r = chm_config_count(c, "svar", &n)) return from_config(r);
    for (std::size_t i = 0; i < n; ++i) {
        if (int r = chm_config_check_keys(c, key("svar", i, nullptr).c_str(), kVarKeys, 5)) return from_config(r);
        chm_servo_system::Var v;
        char buf[64];
        std::size_t t = 0;
        std::int64_t rows = 1, cols = 1;
        if (int r = chm_config_require_string(c, key("svar", i, "name").c_str(), buf, CHM_SVAR_NAME_MAX + 1))
            return from_config(r);
        v.name = buf;
        if (int r = chm_config_require_choice(c, key("svar", i, "type").c_str(), kTypes, 5, &t)) return from_config(r);
        v.type = chm_svar_type_t(t + 1);
        if (int r = chm_config_get_int64(c, key("svar", i, "rows").c_str(), 1, 1, CHM_SVAR_ELEMS_MAX, &rows))
            return from_config(r);
        if (int r = chm_config_get_int64(c, key("svar", i, "cols").c_str(), 1, 1, CHM_SVAR_ELEMS_MAX, &cols))
            return from_config(r);
        if (rows * cols > CHM_SVAR_ELEMS_MAX)
            return from_config(chm_config_error(c, key("svar", i, "cols").c_str(), "%lld x %lld elements, at most %d",
                                                (long long)rows, (long long)cols, CHM_SVAR_ELEMS_MAX));
        if (int r = chm_config_get_string(c, key("svar", i, "unit").c_str(), "", buf, CHM_SVAR_UNIT_MAX + 1))
            return from_config(r);
        v.unit = buf;
        v.rows = std::uint32_t(rows);
        v.cols = std::uint32_t(cols);
        for (const auto& w : s->vars)
            if (w.name == v.name)
                return from_config(chm_config_error(c, key("svar", i, "name").c_str(), "%s is declared twice", v.name.c_str()));
        s->vars.push_back(v);
    }
    return 0;
}

// A module's path: as written when absolute, else beside the config file.
std::string resolve(const std::string& config_path, const char* p) {
    if (p[0] == '/') return p;
    const std::size_t slash = config_path.rfind('/');
    return slash == std::string::npos ? std::string(p) : config_path.substr(0, slash + 1) + p;
}

int read_module(const chm_config_t* c, chm_servo_system* s, std::size_t i) {
    if (int r = chm_config_check_keys(c, key("module", i, nullptr).c_str(), kModuleKeys, 11)) return from_config(r);
    chm_servo_system::Module m;
    char buf[CHM_SERVO_PATH_MAX + 1];
    if (int r = chm_config_require_string(c, key("module", i, "name").c_str(), buf, CHM_SERVO_NAME_MAX + 1))
        return from_config(r);
    m.name = buf;
    if (int r = chm_config_require_string(c, key("module", i, "path").c_str(), buf, sizeof buf)) return from_config(r);
    m.path = resolve(s->path, buf);
    if (m.path.size() > CHM_SERVO_PATH_MAX)
        return from_config(chm_config_error(c, key("module", i, "path").c_str(), "longer than %d bytes once resolved",
                                            CHM_SERVO_PATH_MAX));
    std::int64_t rtpu = 0, prio = 0;
    double rate = 0, deadline_ms = 0, wcet_us = 0;
    int critical = 0, on = 0;
    std::size_t miss = 0;
    if (int r = chm_config_require_int64(c, key("module", i, "rtpu").c_str(), 1, 31, &rtpu)) return from_config(r);
    if (int r = chm_config_require_double(c, key("module", i, "rate_hz").c_str(), 0.01, 10000, &rate))
        return from_config(r);
    const std::uint64_t period = std::uint64_t(std::llround(1e9 / rate));
    if (int r = chm_config_get_double(c, key("module", i, "deadline_ms").c_str(), 0, 0, double(period) / 1e6,
                                      &deadline_ms))
        return from_config(r);
    const double limit_us = (deadline_ms > 0 ? deadline_ms * 1e3 : double(period) / 1e3);
    if (int r = chm_config_get_double(c, key("module", i, "wcet_us").c_str(), 0, 0, limit_us, &wcet_us))
        return from_config(r);
    if (int r = chm_config_get_bool(c, key("module", i, "critical").c_str(), 0, &critical)) return from_config(r);
    if (int r = chm_config_get_int64(c, key("module", i, "priority").c_str(), 0, -1000, 1000, &prio))
        return from_config(r);
    if (int r = chm_config_get_choice(c, key("module", i, "on_miss").c_str(), kMiss, 2, 0, &miss)) return from_config(r);
    if (int r = chm_config_get_bool(c, key("module", i, "on").c_str(), 0, &on)) return from_config(r);
    const std::string pk = key("module", i, "params");
    std::size_t np = 0;
    if (chm_config_type(c, pk.c_str()) != CHM_CONFIG_NONE && chm_config_type(c, pk.c_str()) != CHM_CONFIG_TABLE)
        return from_config(chm_config_error(c, pk.c_str(), "expected a table of parameter = number"));
    if (int r = chm_config_count(c, pk.c_str(), &np)) return from_config(r);
    if (np > CHM_MODULE_PARAMS_MAX)
        return from_config(chm_config_error(c, pk.c_str(), "%zu parameters, at most %d", np, CHM_MODULE_PARAMS_MAX));
    for (std::size_t k = 0; k < np; ++k) {
        char name[40];
        if (int r = chm_config_key(c, pk.c_str(), k, name, 32)) return from_config(r);
        double v = 0;
        if (int r = chm_config_require_double(c, (pk + "." + name).c_str(), -INFINITY, INFINITY, &v))
            return from_config(r);
        m.param_names.emplace_back(name);
        m.param_values.push_back(v);
    }
    for (const auto& o : s->modules)
        if (o.name == m.name && o.spawn.rtpu == int(rtpu))
            return from_config(chm_config_error(c, key("module", i, "name").c_str(),
                                                "a second module %s on RTPU %lld", m.name.c_str(), (long long)rtpu));
    chm_servo_spawn_init(&m.spawn);
    m.spawn.rtpu = int(rtpu);
    m.spawn.period_ns = period;
    m.spawn.deadline_ns = std::uint64_t(std::llround(deadline_ms * 1e6));
    m.spawn.wcet_ns = std::uint64_t(std::llround(wcet_us * 1e3));
    m.spawn.critical = critical;
    m.spawn.priority = int(prio);
    m.spawn.miss_policy = int(miss);
    m.on = on != 0;
    s->rtpus |= 1u << rtpu;
    s->modules.push_back(std::move(m));
    return 0;
}

int open_impl(const char* path, chm_servo_system** out) {
    t_error[0] = 0;
    if (!path || !out) return say(-EINVAL, "chm_servo_system_open: NULL path or out");
    chm_config_t* c = nullptr;
    if (int r = chm_config_open(path, &c)) return from_config(r);
    auto* s = new chm_servo_system;
    s->path = path;
    int r = chm_config_check_keys(c, "", kTopKeys, 3);
    if (r) from_config(r);
    if (r == 0) r = read_vars(c, s);
    std::size_t n = 0;
    if (r == 0 && (r = chm_config_count(c, "module", &n))) from_config(r);
    for (std::size_t i = 0; i < n && r == 0; ++i) r = read_module(c, s, i);
    chm_config_close(c);
    if (r) {
        delete s;
        return r;
    }
    for (auto& m : s->modules) {  // the pointers spawn takes, now that the vector is final
        for (auto& p : m.param_names) m.param_ptrs.push_back(p.c_str());
        m.spawn.path = m.path.c_str();
        m.spawn.name = m.name.c_str();
        m.spawn.n_params = m.param_values.size();
        m.spawn.param_names = m.param_ptrs.data();
        m.spawn.param_values = m.param_values.data();
    }
    *out = s;
    return 0;
}

int declare_impl(chm_servo_system* s) {
    t_error[0] = 0;
    if (!s) return say(-EINVAL, "chm_servo_system_declare: NULL system");
    for (const auto& v : s->vars) {
        chm_svar_decl_t d{v.name.c_str(), v.type, v.rows, v.cols, v.unit.c_str()};
        if (int r = chm_svar_declare(&d)) return say(r, "%s: %s", s->path.c_str(), chm_bp_last_error());
    }
    return 0;
}

void kill_spawned(chm_servo_system* s) {
    for (auto& m : s->modules)
        if (m.spawned) (void)chm_servo_kill(m.id), m.spawned = false;
}

int spawn_impl(chm_servo_system* s) {
    t_error[0] = 0;
    if (!s) return say(-EINVAL, "chm_servo_system_spawn: NULL system");
    if (int r = chm_servo_take(s->rtpus)) return say(r, "%s: %s", s->path.c_str(), chm_servo_last_error());
    for (auto& m : s->modules) {
        if (m.spawned) continue;
        if (int r = chm_servo_spawn(&m.spawn, &m.id)) {
            say(r, "%s: module %s on RTPU %d: %s", s->path.c_str(), m.name.c_str(), m.spawn.rtpu,
                chm_servo_last_error());
            kill_spawned(s);
            return r;
        }
        m.spawned = true;
    }
    return 0;
}

int start_impl(chm_servo_system* s, uint64_t* at) {
    t_error[0] = 0;
    if (!s) return say(-EINVAL, "chm_servo_system_start: NULL system");
    std::vector<chm_servo_module_t> on;
    for (auto& m : s->modules) {
        if (!m.spawned) return say(-ESRCH, "%s: module %s is not spawned", s->path.c_str(), m.name.c_str());
        if (m.on) on.push_back(m.id);
    }
    if (on.empty()) return 0;
    if (int r = chm_servo_switch(nullptr, 0, on.data(), on.size(), 0, at))
        return say(r, "%s: %s", s->path.c_str(), chm_servo_last_error());
    return 0;
}

}  // namespace

extern "C" {

int chm_servo_system_open(const char* path, chm_servo_system_t** out) {
    return chm::ipc::leave(open_impl(path, out), "chm_servo_system_open");
}
int chm_servo_system_declare(chm_servo_system_t* s) {
    return chm::ipc::leave(declare_impl(s), "chm_servo_system_declare");
}
int chm_servo_system_spawn(chm_servo_system_t* s) { return chm::ipc::leave(spawn_impl(s), "chm_servo_system_spawn"); }
int chm_servo_system_start(chm_servo_system_t* s, uint64_t* at_ns) {
    return chm::ipc::leave(start_impl(s, at_ns), "chm_servo_system_start");
}

size_t chm_servo_system_modules(const chm_servo_system_t* s) { return s ? s->modules.size() : 0; }

int chm_servo_system_module_at(const chm_servo_system_t* s, size_t i, chm_servo_system_entry_t* out) {
    if (!s || !out || i >= s->modules.size()) return say(-EINVAL, "chm_servo_system_module_at: no module %zu", i);
    const auto& m = s->modules[i];
    out->name = m.name.c_str();
    out->path = m.path.c_str();
    out->rtpu = m.spawn.rtpu;
    out->period_ns = m.spawn.period_ns;
    out->on = m.on;
    out->spawned = m.spawned;
    out->id = m.id;
    out->critical = m.spawn.critical;
    out->priority = m.spawn.priority;
    out->deadline_ns = m.spawn.deadline_ns;
    out->wcet_ns = m.spawn.wcet_ns;
    return 0;
}

int chm_servo_system_find(const chm_servo_system_t* s, const char* name, chm_servo_module_t* out) {
    if (!s || !name || !out) return say(-EINVAL, "chm_servo_system_find: NULL argument");
    for (const auto& m : s->modules)
        if (m.name == name) {
            if (!m.spawned) return say(-ESRCH, "module %s is not spawned", name);
            *out = m.id;
            return 0;
        }
    return say(-ENOENT, "%s has no module %s", s->path.c_str(), name);
}

int chm_servo_system_svar(const chm_servo_system_t* s, size_t i, chm_svar_decl_t* out) {
    if (!s || !out || i >= s->vars.size()) return say(-EINVAL, "chm_servo_system_svar: no variable %zu", i);
    const auto& v = s->vars[i];
    *out = chm_svar_decl_t{v.name.c_str(), v.type, v.rows, v.cols, v.unit.c_str()};
    return 0;
}
size_t chm_servo_system_svars(const chm_servo_system_t* s) { return s ? s->vars.size() : 0; }

void chm_servo_system_close(chm_servo_system_t* s) { delete s; }

const char* chm_servo_system_last_error(void) { return t_error; }

}  // extern "C"
