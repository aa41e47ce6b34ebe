// `chimera svar plan CONFIG`: the state-variable traffic of a system
// before it runs, as the paper claims for the VMEbus: for each module, the
// bytes its copy-in and copy-out move per cycle and per second, and the
// totals per RTPU and for the system. Reads the system's configuration file
// (chimera/servo.h, "Systems") and each module's descriptor (the shared
// object is opened, never run: no entry point is called). Also refuses a
// layout in which two modules switched on at start write one variable.
#include <dlfcn.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <map>
#include <string>
#include <vector>

#include "chimera/module.h"
#include "chimera/servo.h"
#include "chimera/svar.h"
#include "cmd.hpp"

namespace chimera_cmd {

namespace {

std::size_t elem_bytes(chm_svar_type_t t) {
    return t == CHM_SVAR_DOUBLE ? 8 : t == CHM_SVAR_BOOL ? 1 : 4;
}

struct Row {
    std::string name, module;
    int rtpu;
    double rate;
    std::size_t in, out;
};

}  // namespace

int cmd_svar_plan(const char* config) {
    chm_servo_system_t* sys = nullptr;
    if (int r = chm_servo_system_open(config, &sys)) {
        say("%s", chm_servo_system_last_error());
        return r == -ENOENT || r == -EBADMSG ? 2 : 1;
    }
    std::map<std::string, std::size_t> bytes;
    for (std::size_t i = 0; i < chm_servo_system_svars(sys); ++i) {
        chm_svar_decl_t d;
        (void)chm_servo_system_svar(sys, i, &d);
        bytes[d.name] = std::size_t(d.rows) * d.cols * elem_bytes(d.type);
    }
    std::vector<Row> rows;
    std::map<std::string, std::string> writer;  // variable -> module switched on at start
    int status = 0;
    for (std::size_t i = 0; i < chm_servo_system_modules(sys) && status == 0; ++i) {
        chm_servo_system_entry_t e;
        (void)chm_servo_system_module_at(sys, i, &e);
        // Lazy: a module's calls into libchimera stay unresolved; nothing runs.
        void* dl = dlopen(e.path, RTLD_LAZY | RTLD_LOCAL);
        const auto* d = dl ? static_cast<const chm_module_desc_t*>(dlsym(dl, CHM_MODULE_SYMBOL)) : nullptr;
        if (!d || d->abi != CHM_MODULE_ABI) {
            say("%s: module %s: %s", config, e.name,
                !dl ? dlerror() : !d ? "no chm_module descriptor" : "another descriptor ABI");
            status = 1;
        }
        Row row{e.name, d ? d->name : "", e.rtpu, 1e9 / double(e.period_ns), 0, 0};
        for (int dir = 0; dir < 2 && status == 0; ++dir) {
            const std::size_t n = dir ? d->n_outputs : d->n_inputs;
            for (std::size_t k = 0; k < n && status == 0; ++k) {
                const char* v = dir ? d->outputs[k] : d->inputs[k];
                auto it = bytes.find(v);
                if (it == bytes.end()) {
                    say("%s: module %s uses state variable %s, which the file does not declare", config, e.name, v);
                    status = 2;
                    break;
                }
                (dir ? row.out : row.in) += it->second;
                if (dir && e.on) {
                    auto [w, fresh] = writer.emplace(v, e.name);
                    if (!fresh) {
                        say("%s: state variable %s is written by both %s and %s, switched on at start", config, v,
                            w->second.c_str(), e.name);
                        status = 2;
                    }
                }
            }
        }
        if (dl) dlclose(dl);
        rows.push_back(row);
    }
    chm_servo_system_close(sys);
    if (status) return status;
    std::printf("%-20s %-16s %4s %9s %10s %10s %12s  %s\n", "module", "descriptor", "rtpu", "rate Hz", "in B/cyc",
                "out B/cyc", "B/s", "on at start");
    std::map<int, double> per_rtpu;
    double total = 0, total_on = 0;
    sys = nullptr;
    (void)chm_servo_system_open(config, &sys);
    for (std::size_t i = 0; i < rows.size(); ++i) {
        const Row& r = rows[i];
        chm_servo_system_entry_t e;
        (void)chm_servo_system_module_at(sys, i, &e);
        const double bps = double(r.in + r.out) * r.rate;
        std::printf("%-20s %-16s %4d %9.6g %10zu %10zu %12.0f  %s\n", r.name.c_str(), r.module.c_str(), r.rtpu,
                    r.rate, r.in, r.out, bps, e.on ? "yes" : "no");
        if (e.on) per_rtpu[r.rtpu] += bps, total_on += bps;
        total += bps;
    }
    chm_servo_system_close(sys);
    for (auto& [rtpu, bps] : per_rtpu) std::printf("RTPU %d, modules on at start: %.0f B/s\n", rtpu, bps);
    std::printf("modules on at start: %.0f B/s; every module on at once: %.0f B/s\n", total_on, total);
    return 0;
}

}  // namespace chimera_cmd
