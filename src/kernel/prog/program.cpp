// Control programs as shared objects: dlopen, make their code preemptible,
// spawn main(argc, argv). Programs stay loaded until chm_kernel_fini (a
// task spawned by main may still run their code after main returns).
#include <cerrno>
#include <cstdarg>
#include <climits>
#include <cstdio>
#include <cstring>
#include <dlfcn.h>
#include <link.h>
#include <sys/stat.h>

#include "chimera/mem.h"
#include "chimera/program.h"
#include "kernel.hpp"
#include "kernel/err/last.hpp"
#include "prog/trust.hpp"

namespace chm::kernel {
namespace {

using MainFn = int (*)(int, char**);

struct Program {
    bool used = false;
    void* handle = nullptr;
    MainFn main = nullptr;
    int argc = 0;
    char** argv = nullptr;  // one chm_malloc block: pointers, then strings
    chm_tid_t task = CHM_TID_NONE;
    bool returned = false;
    int status = 0;
};

Program g_programs[CHM_PROGRAM_MAX];
char g_error[768];

void set_error(const char* what) {
    std::snprintf(g_error, sizeof g_error, "%s", what ? what : "");
    if (g_error[0]) kernel::err_last_set(g_error);  // chm_err_last
}

// "PATH: cause", the file named once, and `e` returned.
int refuse(int e, const char* path, const char* fmt, ...) __attribute__((format(printf, 3, 4)));
int refuse(int e, const char* path, const char* fmt, ...) {
    const int k = std::snprintf(g_error, sizeof g_error, "%s: ", path ? path : "(null)");
    va_list ap;
    va_start(ap, fmt);
    if (k > 0 && std::size_t(k) < sizeof g_error) std::vsnprintf(g_error + k, sizeof g_error - std::size_t(k), fmt, ap);
    va_end(ap);
    kernel::err_last_set(g_error);  // chm_err_last
    return e;
}

// argv as main expects it, in one block the program owns.
char** copy_args(int argc, const char* const* argv) {
    std::size_t bytes = sizeof(char*) * std::size_t(argc + 1);
    for (int i = 0; i < argc; ++i) bytes += std::strlen(argv[i] ? argv[i] : "") + 1;
    auto** out = static_cast<char**>(chm_malloc(bytes));
    if (!out) return nullptr;
    char* text = reinterpret_cast<char*>(out + argc + 1);
    for (int i = 0; i < argc; ++i) {
        const char* a = argv[i] ? argv[i] : "";
        const std::size_t n = std::strlen(a) + 1;
        std::memcpy(text, a, n);
        out[i] = text;
        text += n;
    }
    out[argc] = nullptr;
    return out;
}

void run_main(void* arg) {
    auto* p = static_cast<Program*>(arg);
    p->status = p->main(p->argc, p->argv);
    p->returned = true;
}

void unload(Program* p) {
    if (p->main) {
        IrqGuard guard;
        port::preemptible_object_remove(reinterpret_cast<const void*>(p->main));
    }
    if (p->handle) dlclose(p->handle);
    chm_free(p->argv);
    *p = Program{};
}

}  // namespace

void programs_unload_all() {
    for (Program& p : g_programs)
        if (p.used) unload(&p);
}

}  // namespace chm::kernel

using namespace chm::kernel;
namespace port = chm::port;

extern "C" {

int chm_program_load(const char* path, int argc, const char* const* argv,
                     const chm_task_attr_t* attr, chm_tid_t* out_main) {
    set_error(nullptr);
    if (!path || !*path) return refuse(-EINVAL, path, "no program path");
    if (argc < 0 || (argc > 0 && !argv)) return refuse(-EINVAL, path, "argc %d with argv %s", argc, argv ? "set" : "NULL");
    if (!g_k.initialised) return refuse(-EPERM, path, "the kernel is not initialised (chm_kernel_init first)");
    // The file dlopen gets is the one checked: every link resolved, and no
    // one but us or root can change it or the directories above it. The
    // check's message names the file and the cause.
    char real[PATH_MAX];
    if (int e = program_path_check(path, real, sizeof real, g_error, sizeof g_error)) return e;
    // A program linked against libchimera would bring a second copy of it.
    if (int e = program_needs_libchimera(real, g_error, sizeof g_error)) return e;
    Program* p = nullptr;
    for (Program& q : g_programs) {
        if (!q.used) {
            p = &q;
            break;
        }
    }
    if (!p) return refuse(-ENOSPC, real, "%d programs are loaded already (CHM_PROGRAM_MAX)", CHM_PROGRAM_MAX);
    p->used = true;
    // RTLD_LOCAL: two programs may both define helpers of the same name.
    p->handle = dlopen(real, RTLD_NOW | RTLD_LOCAL);
    if (!p->handle) {
        // dlerror names the program ("PATH: invalid ELF header") or only
        // a library it needs ("libx.so: cannot open shared object file"):
        // the file is named once either way.
        const char* d = dlerror();
        if (!d) d = "dlopen failed";
        if (std::strncmp(d, real, std::strlen(real)) == 0) set_error(d);
        else refuse(0, real, "%s", d);
        *p = Program{};
        return -ENOEXEC;
    }
    p->main = reinterpret_cast<MainFn>(dlsym(p->handle, "main"));
    Dl_info info{};
    link_map* lm = nullptr;
    if (!p->main || !dladdr(reinterpret_cast<void*>(p->main), &info) ||
        dlinfo(p->handle, RTLD_DI_LINKMAP, &lm) != 0 || !lm || info.dli_fname != lm->l_name) {
        // No main of its own (dlsym may find the executable's through a
        // dependency): refuse rather than run somebody else's.
        refuse(0, real, "no main: a control program defines int main(int argc, char** argv) (the symbol main "
                        "is missing%s)", p->main ? " from the object itself: the one found belongs to another" : "");
        p->main = nullptr;
        unload(p);
        return -ENOEXEC;
    }
    p->argc = argc;
    p->argv = copy_args(argc, argv);
    if (!p->argv) {
        unload(p);
        return refuse(-ENOMEM, real, "no memory for its arguments");
    }
    {
        IrqGuard guard;
        if (port::preemptible_object_add(reinterpret_cast<const void*>(p->main)) < 0) {
            refuse(0, real, "loaded, but its code segments were not found (its code is not preemptible)");
        }
    }
    chm_task_attr_t a;
    if (attr) {
        a = *attr;
    } else {
        chm_task_attr_init(&a);
    }
    char name[CHM_TASK_NAME_MAX + 1];
    if (!a.name) {  // the file's name, without directory, cut to fit
        const char* base = std::strrchr(path, '/');
        std::snprintf(name, sizeof name, "%s", base ? base + 1 : path);
        a.name = name;
    }
    chm_tid_t tid = CHM_TID_NONE;
    if (int e = chm_task_spawn(&tid, run_main, p, &a)) {
        unload(p);
        return refuse(e, real, "cannot start main as a task: %s", std::strerror(-e));
    }
    p->task = tid;
    if (out_main) *out_main = tid;
    return int(p - g_programs);
}

int chm_program_status(int program, int* status) {
    if (program < 0 || program >= CHM_PROGRAM_MAX || !g_programs[program].used) return -EINVAL;
    const Program& p = g_programs[program];
    if (p.returned) {
        if (status) *status = p.status;
        return 0;
    }
    chm_task_status_t st;
    if (chm_task_status(p.task, &st) != 0) return -ECHILD;
    return -EAGAIN;
}

const char* chm_program_error(void) { return g_error; }

}  // extern "C"
