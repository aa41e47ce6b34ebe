// Error signals: the module registry, each task's handler set, scopes,
// marks, the raise itself (handler lookup and its outcome) and aborting a
// task. Processor exceptions enter through err/fault.cpp, the UNIX wrappers
// through err/unix.cpp; both end in err_raise().
#include <cerrno>
#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <new>
#include <sys/syscall.h>
#include <unistd.h>

#include "chimera/dev.h"
#include "chimera/mem.h"
#include "err/err_internal.hpp"
#include "port.hpp"

namespace chm::kernel {

bool err_on_fault_stack(const Tcb* t);  // err/fault.cpp
bool err_kernel_thread();               // err/fault.cpp
void err_fault_stack_release_locked(Tcb* t);

namespace {

constexpr unsigned kMarkMagic = 0x4d41524bu;  // "MARK"
constexpr unsigned kQuiet = 0x80000000u;  // in info.flags: no default line

struct Module {
    char name[32];
    const chm_err_code_t* codes;
    std::size_t ncodes;
};

const chm_err_code_t kKernelCodes[] = {
    {CHM_EK_DEADLINE, "deadline missed"},
    {CHM_EK_HEAP, "heap corrupt"},
    {CHM_EK_CANARY, "stack canary overwritten"},
};
const chm_err_code_t kCpuCodes[] = {
    {CHM_ECPU_SEGV, "segmentation fault"},
    {CHM_ECPU_BUS, "bus error"},
    {CHM_ECPU_FPE, "arithmetic exception"},
    {CHM_ECPU_ILL, "illegal instruction"},
    {CHM_ECPU_STACK, "stack overflow"},
};

// Module ids are indices; 0 is never used. Registration happens under the
// mask on the kernel thread or before the kernel starts.
Module g_modules[CHM_ERR_MODULES_MAX + 1] = {
    {},
    {"kernel", kKernelCodes, sizeof kKernelCodes / sizeof kKernelCodes[0]},
    {"cpu", kCpuCodes, sizeof kCpuCodes / sizeof kCpuCodes[0]},
    {"unix", nullptr, 0},
};
int g_nmodules = 3;
int g_rtpu = -1;  // -1: the kernel config's rtpu_id

bool module_ok(int m) { return m > 0 && m <= g_nmodules; }

// Statuses that mean "the call could not do its job": bugs and missing
// resources. Everything else is an outcome the caller expects to handle.
bool is_error_status(int status) {
    switch (-status) {
    case EINVAL: case ESRCH: case EPERM: case ENOMEM: case ENAMETOOLONG:
    case ENOSPC: case EEXIST: case ENOENT: case EBADF: case EFAULT:
        return true;
    default:
        return false;
    }
}

Tcb* task_here() {
    return err_kernel_thread() ? g_k.current : nullptr;
}

ErrBinding* find_binding(ErrTask* e, int module, int code) {
    for (int i = 0; i < e->nbind; ++i)
        if (e->bind[i].module == module && e->bind[i].code == code) return &e->bind[i];
    return nullptr;
}

int set_binding(int module, int code, chm_err_handler_t h, void* arg) {
    Tcb* cur = task_here();
    if (!cur) return -EPERM;
    if (!module_ok(module) || code < 0) return -EINVAL;
    ErrTask* e = err_task(cur, h != nullptr);
    if (!e) return h ? -ENOMEM : 0;
    ErrBinding* b = find_binding(e, module, code);
    if (!h) {
        if (b) *b = e->bind[--e->nbind];
        return 0;
    }
    if (!b) {
        if (e->nbind == ErrTask::kBindings) return -ENOSPC;
        b = &e->bind[e->nbind++];
    }
    *b = ErrBinding{module, code, h, arg};
    return 0;
}

bool mark_in_chain(ErrTask* e, const chm_err_mark_t* m) {
    for (chm_err_mark_t* x = e ? e->mark : nullptr; x; x = static_cast<chm_err_mark_t*>(x->link[0]))
        if (x == m) return true;
    return false;
}

// Call one handler with the task marked as "inside a handler".
chm_err_action_t call(ErrTask* e, chm_err_handler_t h, void* arg, const chm_err_info_t& info) {
    e->depth = e->depth + 1;
    const chm_err_action_t a = h(&info, arg);
    e->depth = e->depth - 1;
    return a;
}

chm_err_action_t run_handlers(ErrTask* e, const chm_err_info_t& info) {
    chm_err_action_t a = CHM_ERR_PASS;
    for (ErrScope* s = e->scope; s && a == CHM_ERR_PASS; s = s->outer) a = call(e, s->h, s->arg, info);
    if (a == CHM_ERR_PASS)
        if (ErrBinding* b = find_binding(e, info.module, info.code)) {
            const ErrBinding copy = *b;  // the handler may change the set
            a = call(e, copy.h, copy.arg, info);
        }
    if (a == CHM_ERR_PASS)
        if (ErrBinding* b = find_binding(e, info.module, 0)) {
            const ErrBinding copy = *b;
            a = call(e, copy.h, copy.arg, info);
        }
    if (a == CHM_ERR_PASS && e->task_h) a = call(e, e->task_h, e->task_arg, info);
    return a;
}

[[noreturn]] void jump_to(ErrTask* e, chm_err_mark_t* m, int code) {
    e->mark = m;  // marks set after it are gone with their frames
    e->scope = static_cast<ErrScope*>(m->link[1]);
    e->depth = m->depth;
    // The backplane calls entered since the mark are left with their
    // frames: what they hold is given back, and an end or restart owed to
    // them is carried out now (task/holds.hpp).
    task_leave_calls_to(static_cast<Tcb*>(m->link[2]), unsigned(m->code) & 0xFF, (unsigned(m->code) >> 8) & 0xFF);
    std::longjmp(m->jb, code > 0 ? code : 1);
}

}  // namespace

int err_rtpu() { return g_rtpu >= 0 ? g_rtpu : g_k.cfg.rtpu_id; }

ErrTask* err_task(Tcb* t, bool create) {
    if (t->err || !create) return t->err;
    void* p = chm_malloc(sizeof(ErrTask));
    if (!p) return nullptr;
    t->err = new (p) ErrTask();
    return t->err;
}

int err_raise(chm_err_info_t& info) {
    if (!info.module_name) info.module_name = chm_err_module_name(info.module);
    if (!info.message) info.message = chm_err_message(info.module, info.code);
    Tcb* cur = task_here();
    if (!cur) {  // no task to abort: report and go on
        info.task = CHM_TID_NONE;
        chm_err_default_handler(&info, nullptr);
        return info.status;
    }
    info.task = tid_of(cur);
    ErrTask* e = err_task(cur, false);
    chm_err_action_t a = CHM_ERR_PASS;
    // Inside a handler an error goes straight to the default: no recursion.
    if (e && e->depth == 0) a = run_handlers(e, info);
    if (a == CHM_ERR_PASS) {
        if (!(info.flags & kQuiet)) a = chm_err_default_handler(&info, nullptr);
        if (info.flags & CHM_ERR_DEFAULT_CONTINUES) a = CHM_ERR_CONTINUE;
    }
    e = err_task(cur, false);  // a handler may have created it
    switch (a) {
    case CHM_ERR_CONTINUE:
        if (!(info.flags & CHM_ERR_FATAL)) return info.status;
        chm_err_default_handler(&info, nullptr);  // say why the task ends
        break;
    case CHM_ERR_TO_MARK:
        if (e && e->mark && !err_on_fault_stack(cur)) jump_to(e, e->mark, info.code);
        {
            chm_err_info_t why = info;
            why.detail = err_on_fault_stack(cur) ? "the task's stack is exhausted: no return to a mark"
                                                 : "no mark set to return to";
            chm_err_default_handler(&why, nullptr);
        }
        break;
    default:
        break;
    }
    err_abort_current();
}

int err_call_failed(int status, const char* call) {
    err_last_failed(call, status, false);  // kernel calls set no message of their own
    if (!is_error_status(status)) return status;
    Tcb* cur = task_here();
    if (!cur || !cur->err || !cur->err->global) return status;
    const std::uint32_t nest = port::g_irq.nest;
    if (nest > 1) return status;  // not from a task's own call: never run handlers here
    chm_err_info_t info{};
    info.module = CHM_ERR_KERNEL;
    info.code = -status;
    info.call = call;
    info.status = status;
    if (status == -EFAULT && call && std::strcmp(call, "chm_mem_check") == 0) info.code = CHM_EK_HEAP;
    const int saved = errno;
    if (nest == 1) port::irq_restore();
    err_raise(info);
    if (nest == 1) port::irq_disable();
    errno = saved;
    return status;
}

void err_abort_current() {
    // Its devices first, in task context: actuators it drives go to their
    // safe stop and its descriptors close before anything else runs.
    chm_dev_task_abort(chm_task_self());
    // Its end hooks run before its end; the end reason (not a global,
    // which another task's abort could overwrite meanwhile) says it was
    // aborted, so its semaphores pass on with owner-died semantics.
    task_end_current(CHM_TASK_ABORTED, 0);
}

void err_task_ended_locked(Tcb* t) {
    if (t->held) sem_release_held_locked(t, t->end_reason == CHM_TASK_ABORTED);
    if (t->stack_lo && !stack_canary_ok(t)) {
        chm_err_info_t info{};
        info.module = CHM_ERR_KERNEL;
        info.code = CHM_EK_CANARY;
        info.module_name = "kernel";
        info.message = "stack canary overwritten";
        info.detail = "found when the task ended";
        info.task = tid_of(t);
        LineBuf b;
        err_format_line(b, info, t->name);
        (void)!syscall(SYS_write, 2, b.s, b.n);  // mask held: never the interposed write
    }
    err_fault_stack_release_locked(t);
    if (t->err) {
        t->err->~ErrTask();
        chm_free(t->err);
        t->err = nullptr;
    }
}

void err_deadline_missed_locked(const chm_deadline_info_t& d) {
    char detail[96];
    std::snprintf(detail, sizeof detail, "miss %llu, cycle %llu, %llu ns late",
                  static_cast<unsigned long long>(d.misses), static_cast<unsigned long long>(d.cycle),
                  static_cast<unsigned long long>(d.now_ns - d.deadline_ns));
    chm_err_info_t info{};
    info.module = CHM_ERR_KERNEL;
    info.code = CHM_EK_DEADLINE;
    info.detail = detail;
    info.flags = CHM_ERR_DEFAULT_CONTINUES;
    if (d.misses & (d.misses - 1)) info.flags |= kQuiet;  // a line for miss 1, 2, 4, 8...
    port::irq_restore();
    err_raise(info);  // continue: the late cycle runs on
    port::irq_disable();
}

}  // namespace chm::kernel

using namespace chm::kernel;
namespace port = chm::port;

extern "C" {

int chm_err_module_register(const char* name, const chm_err_code_t* codes, size_t ncodes) {
    if (!name || !*name || std::strlen(name) >= sizeof g_modules[0].name) return record_failure(-EINVAL, "chm_err_module_register");
    if (!codes && ncodes) return record_failure(-EINVAL, "chm_err_module_register");
    for (std::size_t i = 0; i < ncodes; ++i)
        if (codes[i].code <= 0) return record_failure(-EINVAL, "chm_err_module_register");
    IrqGuard guard;
    for (int m = 1; m <= g_nmodules; ++m)
        if (std::strcmp(g_modules[m].name, name) == 0) return record_failure(-EEXIST, "chm_err_module_register");
    if (g_nmodules == CHM_ERR_MODULES_MAX) return record_failure(-ENOSPC, "chm_err_module_register");
    Module& m = g_modules[++g_nmodules];
    std::strcpy(m.name, name);
    m.codes = codes;
    m.ncodes = ncodes;
    return g_nmodules;
}

int chm_err_module_find(const char* name) {
    if (!name) return record_failure(-EINVAL, "chm_err_module_find");
    for (int m = 1; m <= g_nmodules; ++m)
        if (std::strcmp(g_modules[m].name, name) == 0) return m;
    return record_failure(-ENOENT, "chm_err_module_find");
}

const char* chm_err_module_name(int module) { return module_ok(module) ? g_modules[module].name : nullptr; }

const char* chm_err_message(int module, int code) {
    if (module_ok(module))
        for (std::size_t i = 0; i < g_modules[module].ncodes; ++i)
            if (g_modules[module].codes[i].code == code) return g_modules[module].codes[i].message;
    if ((module == CHM_ERR_KERNEL || module == CHM_ERR_UNIX) && code > 0 && code < 1000)
        return strerror(code);
    return "unknown error";
}

void chm_err_rtpu_set(int rtpu) { g_rtpu = rtpu; }

int chm_err_invoke_at(int module, int code, const char* file, int line) {
    if (!module_ok(module) || code <= 0) return record_failure(-EINVAL, "chm_err_invoke_at");
    chm_err_info_t info{};
    info.module = module;
    info.code = code;
    info.file = file;
    info.line = line;
    info.status = 0;
    return err_raise(info);
}

int chm_err_invoke(int module, int code) { return chm_err_invoke_at(module, code, nullptr, 0); }

chm_err_action_t chm_err_default_handler(const chm_err_info_t* info, void*) {
    if (!info) return CHM_ERR_ABORT;
    Tcb* t = info->task != CHM_TID_NONE ? tcb_lookup(info->task) : nullptr;
    LineBuf b;
    err_format_line(b, *info, t ? t->name : nullptr);
    (void)!write(2, b.s, b.n);  // one write: the line is never interleaved
    return CHM_ERR_ABORT;
}

int chm_err_on_code(int module, int code, chm_err_handler_t h, void* arg) {
    if (code <= 0) return raise_or_return(-EINVAL, "chm_err_on_code");
    return raise_or_return(set_binding(module, code, h, arg), "chm_err_on_code");
}

int chm_err_on_module(int module, chm_err_handler_t h, void* arg) {
    return raise_or_return(set_binding(module, 0, h, arg), "chm_err_on_module");
}

int chm_err_on_task(chm_err_handler_t h, void* arg) {
    Tcb* cur = task_here();
    if (!cur) return record_failure(-EPERM, "chm_err_on_task");
    ErrTask* e = err_task(cur, h != nullptr);
    if (!e) return h ? -ENOMEM : 0;
    e->task_h = h;
    e->task_arg = arg;
    return 0;
}

int chm_err_scope_push(chm_err_scope_t* scope, chm_err_handler_t h, void* arg) {
    Tcb* cur = task_here();
    if (!cur) return record_failure(-EPERM, "chm_err_scope_push");
    if (!scope || !h) return raise_or_return(-EINVAL, "chm_err_scope_push");
    ErrTask* e = err_task(cur, true);
    if (!e) return raise_or_return(-ENOMEM, "chm_err_scope_push");
    auto* s = reinterpret_cast<ErrScope*>(scope);
    *s = ErrScope{e->scope, h, arg, s};
    e->scope = s;
    return 0;
}

int chm_err_scope_pop(chm_err_scope_t* scope) {
    Tcb* cur = task_here();
    if (!cur) return record_failure(-EPERM, "chm_err_scope_pop");
    ErrTask* e = err_task(cur, false);
    auto* s = reinterpret_cast<ErrScope*>(scope);
    if (!e || !s || e->scope != s || s->self != s) return raise_or_return(-EINVAL, "chm_err_scope_pop");
    e->scope = s->outer;
    s->self = nullptr;
    return 0;
}

jmp_buf* chm_err_mark_arm_(chm_err_mark_t* m) {
    Tcb* cur = task_here();
    ErrTask* e = cur ? err_task(cur, true) : nullptr;
    if (!e) {  // outside a task (or no memory): a plain setjmp, never linked
        m->magic = 0;
        return &m->jb;
    }
    if (mark_in_chain(e, m)) {
        e->mark = m;  // set again (a loop): marks set after it are dropped
    } else {
        m->link[0] = e->mark;
        e->mark = m;
    }
    m->link[1] = e->scope;
    m->link[2] = cur;
    m->magic = kMarkMagic;
    // `code` (not read otherwise) keeps the task's backplane holds and
    // call depth at this mark, for a return to it from inside a call.
    m->code = int(cur->nholds | unsigned(cur->call_depth) << 8);
    m->depth = e->depth;
    return &m->jb;
}

int chm_err_unmark(chm_err_mark_t* m) {
    Tcb* cur = task_here();
    if (!cur) return record_failure(-EPERM, "chm_err_unmark");
    ErrTask* e = err_task(cur, false);
    if (!m || m->magic != kMarkMagic || !mark_in_chain(e, m))
        return raise_or_return(-EINVAL, "chm_err_unmark");
    e->mark = static_cast<chm_err_mark_t*>(m->link[0]);
    m->magic = 0;
    return 0;
}

void chm_err_jump(chm_err_mark_t* m, int code) {
    Tcb* cur = task_here();
    ErrTask* e = cur ? err_task(cur, false) : nullptr;
    if (e && m && m->magic == kMarkMagic && m->link[2] == cur && mark_in_chain(e, m) &&
        !err_on_fault_stack(cur))
        jump_to(e, m, code);
    chm_err_info_t info{};
    info.module = CHM_ERR_KERNEL;
    info.code = EINVAL;
    info.call = "chm_err_jump";
    info.detail = "not a live mark of this task";
    info.task = cur ? tid_of(cur) : CHM_TID_NONE;
    info.module_name = "kernel";
    info.message = strerror(EINVAL);
    chm_err_default_handler(&info, nullptr);
    if (cur) err_abort_current();
    _exit(CHM_ERR_FAILSTOP_STATUS);  // outside a task there is nothing to return to
}

int chm_err_global(int on) {
    Tcb* cur = task_here();
    if (!cur) return record_failure(-EPERM, "chm_err_global");
    ErrTask* e = err_task(cur, on != 0);
    if (!e) return on ? -ENOMEM : 0;
    const int was = e->global;
    e->global = on != 0;
    return was;
}

int chm_err_global_get(void) {
    Tcb* cur = task_here();
    return cur && cur->err && cur->err->global;
}

}  // extern "C"
