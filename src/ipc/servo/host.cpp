// The module table of one RTPU: loading a module and checking its
// descriptor, parameters, entry points run in tasks of their own, ERROR,
// kill, and the calls module code makes (chimera/module.h).
#include <algorithm>
#include <cerrno>
#include <climits>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <dlfcn.h>
#include <new>

#include "chimera/bp.h"
#include "chimera/err.h"
#include "chimera/kernel.h"
#include "ipc/backplane/backplane.hpp"
#include "ipc/servo/host.hpp"
#include "kernel.hpp"
#include "prog/trust.hpp"

namespace chm::servo {

namespace {

chm_module g_mods[CHM_SERVO_MODULES_MAX];
std::uint32_t g_controller = 0;  // backplane token of the controlling process, 0: none
std::uint32_t g_gen = 0;
constexpr std::uint64_t kEntryTimeoutNs = 5'000'000'000ull;

const char* entry_name(Entry e) {
    static const char* names[] = {"init", "on", "off", "kill", "clear", "error"};
    return names[e];
}

struct Call {
    chm_module* m;
    Entry e;
    int code;
    int rc = 0;
    bool returned = false;
};

chm_err_action_t record_error(const chm_err_info_t* i, void* arg) {
    return record_error_as(static_cast<chm_module*>(arg), "", i);
}

void entry_task(void* arg) {
    auto* c = static_cast<Call*>(arg);
    (void)chm_err_on_task(record_error, c->m);
    const chm_module_desc_t* d = c->m->desc;
    switch (c->e) {
    case kEntryInit: c->rc = d->init(c->m); break;
    case kEntryOn: c->rc = d->on(c->m); break;
    case kEntryOff: c->rc = d->off(c->m); break;
    case kEntryKill: c->rc = d->kill(c->m); break;
    case kEntryClear: c->rc = d->clear ? d->clear(c->m) : 0; break;
    case kEntryError: c->rc = d->error ? d->error(c->m, c->code) : 0; break;
    }
    c->returned = true;
}

void unload(chm_module* m) {
    if (m->set) (void)chm_svar_set_destroy(m->set);
    std::free(m->state_mem);
    if (m->dl) {
        {
            kernel::IrqGuard guard;
            port::preemptible_object_remove(reinterpret_cast<const void*>(m->desc->cycle));
        }
        dlclose(m->dl);
    }
    const std::uint32_t gen = m->gen;
    const int index = m->index;
    m->~chm_module();
    new (m) chm_module{};
    m->gen = gen;
    m->index = index;
}

// The descriptor's promises, checked before anything of it runs.
int check_desc(const chm_module_desc_t* d, char* why, std::size_t n) {
    auto bad = [&](const char* what) {
        std::snprintf(why, n, "descriptor: %s", what);
        return -ENOEXEC;
    };
    if (d->abi != CHM_MODULE_ABI) {
        std::snprintf(why, n, "descriptor ABI %u, this RTPU runs ABI %u (rebuild the module)", d->abi, CHM_MODULE_ABI);
        return -ENOEXEC;
    }
    if (!d->name || !d->name[0] || std::strlen(d->name) > CHM_SERVO_NAME_MAX) return bad("no name, or too long");
    if (!d->init || !d->on || !d->cycle || !d->off || !d->kill)
        return bad("an entry point is missing (init, on, cycle, off and kill are required)");
    if (d->n_inputs > CHM_MODULE_VARS_MAX || d->n_outputs > CHM_MODULE_VARS_MAX) return bad("more than 16 inputs or outputs");
    if ((d->n_inputs && !d->inputs) || (d->n_outputs && !d->outputs)) return bad("NULL variable list");
    if (d->n_params > CHM_MODULE_PARAMS_MAX || (d->n_params && !d->params)) return bad("more than 16 parameters, or NULL");
    for (std::size_t i = 0; i < d->n_params; ++i) {
        const chm_module_param_t& p = d->params[i];
        if (!p.name || !(p.min <= p.def && p.def <= p.max)) {
            std::snprintf(why, n, "descriptor: parameter %zu (%s): default %g outside [%g, %g]", i, p.name ? p.name : "?",
                          p.def, p.min, p.max);
            return -ENOEXEC;
        }
    }
    if (d->n_safe && !d->safe) return bad("NULL safe-value list");
    for (std::size_t i = 0; i < d->n_safe; ++i) {
        bool found = false;
        for (std::size_t k = 0; k < d->n_outputs; ++k) found |= d->safe[i].output && !std::strcmp(d->safe[i].output, d->outputs[k]);
        if (!found) {
            std::snprintf(why, n, "descriptor: safe value for %s, which is not an output",
                          d->safe[i].output ? d->safe[i].output : "NULL");
            return -ENOEXEC;
        }
    }
    return 0;
}

int param_index(const chm_module* m, const char* name) {
    for (std::size_t i = 0; i < m->desc->n_params; ++i)
        if (!std::strcmp(m->desc->params[i].name, name)) return int(i);
    return -1;
}

}  // namespace

chm_err_action_t record_error_as(chm_module* m, const char* prefix, const chm_err_info_t* i) {
    set_last_error(m, "%s%s error %d (%s)%s%s%s%s", prefix, i->module_name ? i->module_name : "?", i->code,
                   i->message ? i->message : "", i->call ? " in " : "", i->call ? i->call : "",
                   i->detail ? ": " : "", i->detail ? i->detail : "");
    return CHM_ERR_ABORT;
}

void set_last_error(chm_module* m, const char* fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    std::vsnprintf(m->last_error, sizeof m->last_error, fmt, ap);
    va_end(ap);
}

chm_module* lookup(Ref ref) {
    if (ref.index < 0 || ref.index >= CHM_SERVO_MODULES_MAX) return nullptr;
    chm_module* m = &g_mods[ref.index];
    return m->used && m->gen == ref.gen ? m : nullptr;
}

chm_module* find_name(const char* name) {
    for (chm_module& m : g_mods)
        if (m.used && !std::strncmp(m.name, name, kNameLen)) return &m;
    return nullptr;
}

bool controls(std::uint32_t from) { return g_controller != 0 && g_controller == from; }

int take(std::uint32_t from, char* why, std::size_t n) {
    const bp::Attachment* a = bp::current();
    if (g_controller && g_controller != from && a && bp::token_alive(*a, g_controller, true)) {
        std::snprintf(why, n, "controlled by slot %u", bp::token_slot(g_controller));
        return -EBUSY;
    }
    g_controller = from;
    return 0;
}

int release(std::uint32_t from) {
    if (g_controller == from) g_controller = 0;
    return 0;
}

int run_entry(chm_module* m, Entry e, int code) {
    if ((e == kEntryClear && !m->desc->clear) || (e == kEntryError && !m->desc->error)) return 0;
    Call c{m, e, code};
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    char name[CHM_TASK_NAME_MAX + 1];
    std::snprintf(name, sizeof name, "%.10s.%s", m->name, entry_name(e));
    a.name = name;
    a.priority = m->priority;
    a.joinable = 1;
    chm_tid_t t = CHM_TID_NONE;
    if (int r = chm_task_spawn(&t, entry_task, &c, &a)) {
        set_last_error(m, "%s: cannot spawn its task (%d)", entry_name(e), r);
        return -ECANCELED;
    }
    chm_task_status_t st;
    const int r = chm_task_join(t, kEntryTimeoutNs, &st);
    if (r == -ETIMEDOUT) {
        (void)chm_task_destroy(t);
        (void)chm_task_join(t, CHM_NO_WAIT, nullptr);
        set_last_error(m, "%s did not return within 5 s (its task was destroyed)", entry_name(e));
        return -ECANCELED;
    }
    if (!c.returned) {
        if (!m->last_error[0]) set_last_error(m, "%s ended its task without returning", entry_name(e));
        return -ECANCELED;
    }
    if (c.rc != 0) {
        set_last_error(m, "%s returned %d", entry_name(e), c.rc);
        return -ECANCELED;
    }
    return 0;
}

void enter_error(chm_module* m) {
    m->state.store(CHM_SERVO_ERROR);
    const chm_module_desc_t* d = m->desc;
    if (!d->n_safe) return;
    for (std::size_t i = 0; i < d->n_safe; ++i) {
        chm_svar_info_t info;
        void* p = chm_svar_set_local(m->set, d->safe[i].output);
        if (!p || chm_svar_info(d->safe[i].output, &info)) continue;
        const double v = d->safe[i].value;
        for (std::size_t k = 0; k < std::size_t(info.rows) * info.cols; ++k) {
            switch (info.type) {
            case CHM_SVAR_DOUBLE: static_cast<double*>(p)[k] = v; break;
            case CHM_SVAR_FLOAT: static_cast<float*>(p)[k] = float(v); break;
            case CHM_SVAR_INT32: static_cast<std::int32_t*>(p)[k] = std::int32_t(v); break;
            case CHM_SVAR_UINT32: static_cast<std::uint32_t*>(p)[k] = std::uint32_t(v); break;
            case CHM_SVAR_BOOL: static_cast<unsigned char*>(p)[k] = v != 0; break;
            }
        }
    }
    (void)chm_svar_set_write(m->set);  // -EPERM when it never claimed: nothing of it was ever out
}

int spawn(const SpawnReq& q, const ParamOverride* params, const char* path, Ref* out, char* why, std::size_t n) {
    if (find_name(q.name)) return std::snprintf(why, n, "instance name %s is taken on this RTPU", q.name), -EEXIST;
    chm_module* m = nullptr;
    for (chm_module& x : g_mods)
        if (!x.used) {
            m = &x;
            break;
        }
    if (!m) return std::snprintf(why, n, "%d modules already", CHM_SERVO_MODULES_MAX), -ENOSPC;
    char real[PATH_MAX];
    if (int e = kernel::program_path_check(path, real, sizeof real, why, n)) return e;
    if (int e = kernel::program_needs_libchimera(real, why, n)) return e;
    m->index = int(m - g_mods);
    m->used = true;
    m->gen = ++g_gen;
    std::snprintf(m->name, sizeof m->name, "%s", q.name);
    m->dl = dlopen(real, RTLD_NOW | RTLD_LOCAL);
    if (!m->dl) {
        const char* d = dlerror();
        if (!d) d = "dlopen failed";
        // Named once: dlerror may or may not start with the file.
        std::snprintf(why, n, "%s%s%s", std::strncmp(d, real, std::strlen(real)) ? real : "",
                      std::strncmp(d, real, std::strlen(real)) ? ": " : "", d);
        unload(m);
        return -ENOEXEC;
    }
    m->desc = static_cast<const chm_module_desc_t*>(dlsym(m->dl, CHM_MODULE_SYMBOL));
    if (!m->desc) {
        std::snprintf(why, n, "%s exports no %s descriptor", real, CHM_MODULE_SYMBOL);
        m->dl = (dlclose(m->dl), nullptr);
        unload(m);
        return -ENOEXEC;
    }
    if (int e = check_desc(m->desc, why, n)) {
        m->dl = (dlclose(m->dl), nullptr);
        unload(m);
        return e;
    }
    {
        kernel::IrqGuard guard;
        port::preemptible_object_add(reinterpret_cast<const void*>(m->desc->cycle));  // its code runs in preemptible tasks
    }
    const chm_module_desc_t* d = m->desc;
    m->cycle_fn = d->cycle;
    for (std::size_t i = 0; i < d->n_params; ++i) m->params[i] = d->params[i].def;
    int r = 0;
    for (std::uint32_t i = 0; i < q.n_params && r == 0; ++i) {
        const int k = param_index(m, params[i].name);
        const double v = params[i].value;
        if (k < 0) r = (std::snprintf(why, n, "module %s has no parameter %s", d->name, params[i].name), -ESRCH);
        else if (!(v >= d->params[k].min && v <= d->params[k].max))
            r = (std::snprintf(why, n, "parameter %s = %g outside [%g, %g]", params[i].name, v, d->params[k].min,
                               d->params[k].max),
                 -ERANGE);
        else m->params[k] = v;
    }
    m->period_ns = q.period_ns;
    m->deadline_ns = q.deadline_ns;
    m->wcet_ns = q.wcet_ns;
    m->critical = q.critical;
    m->priority = q.priority;
    m->miss_policy = q.miss_policy;
    if (r == 0 && d->state_size && !(m->state_mem = std::calloc(1, d->state_size)))
        r = (std::snprintf(why, n, "no memory for %zu bytes of state", d->state_size), -ENOMEM);
    if (r == 0) {
        r = chm_svar_set_open(m->name, d->inputs, d->n_inputs, d->outputs, d->n_outputs, &m->set);
        if (r) std::snprintf(why, n, "%s", chm_bp_last_error());
    }
    if (r == 0) {
        m->state.store(CHM_SERVO_OFF);
        if (run_entry(m, kEntryInit) != 0) {
            r = -ECANCELED;
            std::snprintf(why, n, "init: %s", m->last_error);
        }
    }
    if (r) {
        unload(m);
        return r;
    }
    *out = Ref{m->index, m->gen};
    return 0;
}

int control(chm_module* m, const char* param, double value, char* why, std::size_t n) {
    const int k = param_index(m, param);
    if (k < 0) return std::snprintf(why, n, "module %s has no parameter %s", m->desc->name, param), -ESRCH;
    const chm_module_param_t& p = m->desc->params[k];
    if (!(value >= p.min && value <= p.max))
        return std::snprintf(why, n, "parameter %s = %g outside [%g, %g]", param, value, p.min, p.max), -ERANGE;
    if (m->state.load() == CHM_SERVO_ON) {
        m->pending[k] = value;  // the cycle task takes it before its next cycle
        m->pending_mask.fetch_or(1u << k, std::memory_order_release);
    } else {
        m->params[k] = value;
    }
    return 0;
}

int clear(chm_module* m, char* why, std::size_t n) {
    if (m->state.load() != CHM_SERVO_ERROR) return std::snprintf(why, n, "%s is not in ERROR", m->name), -EALREADY;
    if (run_entry(m, kEntryClear) != 0) return std::snprintf(why, n, "clear: %s", m->last_error), -ECANCELED;
    (void)chm_svar_set_release(m->set);
    m->last_error[0] = 0;
    m->state.store(CHM_SERVO_OFF);
    return 0;
}

int kill(chm_module* m, char* why, std::size_t n) {
    int r = 0;
    if (m->state.load() == CHM_SERVO_ON) stop_cycle_task(m);  // runs off on its way out
    if (run_entry(m, kEntryKill) != 0) r = (std::snprintf(why, n, "kill: %s (the module is removed)", m->last_error), 0);
    unload(m);
    return r;
}

void status(const chm_module* m, StatusReply* out) {
    std::memset(out, 0, sizeof *out);
    std::memcpy(out->name, m->name, kNameLen);
    std::snprintf(out->module, sizeof out->module, "%s", m->desc->name);
    out->state = m->state.load();
    out->period_ns = m->period_ns;
    out->cycles = m->cycles;
    out->misses = m->misses;
    out->worst_ns = m->worst_ns;
    out->switched_at = m->switched_at;
    // An instant an earlier switch armed this module for (on, or off),
    // which a later switch must not precede.
    out->pending_at = std::max(m->on_at, m->off_at());
    std::memcpy(out->last_error, m->last_error, sizeof out->last_error);
    out->last_error[sizeof out->last_error - 1] = 0;
}

}  // namespace chm::servo

using namespace chm::servo;

extern "C" {

void* chm_module_var(chm_module_t* m, const char* name) { return m ? chm_svar_set_local(m->set, name) : nullptr; }
const double* chm_module_params(const chm_module_t* m) { return m ? m->params : nullptr; }
double chm_module_param(const chm_module_t* m, const char* name) {
    if (!m || !name) return NAN;
    for (std::size_t i = 0; i < m->desc->n_params; ++i)
        if (!std::strcmp(m->desc->params[i].name, name)) return m->params[i];
    return NAN;
}
void* chm_module_state(chm_module_t* m) { return m ? m->state_mem : nullptr; }
const char* chm_module_name(const chm_module_t* m) { return m ? m->name : nullptr; }
uint64_t chm_module_period_ns(const chm_module_t* m) { return m ? m->period_ns : 0; }
uint64_t chm_module_release_ns(const chm_module_t* m) { return m ? m->release_now : 0; }
uint64_t chm_module_cycles(const chm_module_t* m) { return m ? m->cycles : 0; }

}  // extern "C"
