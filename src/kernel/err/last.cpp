// The last error's text (chm_err_last): one place for every subsystem. A
// failing call leaves its message here, per task (the tasks of an RTPU
// share one thread, so a thread-local would let one task read another's
// error); outside a task, per thread.
//
// Two ways in. A subsystem with something to say (the backplane naming a
// field, a configuration file naming a line) calls err_last_set with its
// message as it fails. A call's failure exit (the kernel's raise_or_return,
// the IPC calls' leave) calls err_last_failed: it keeps a message set since
// the last exit and otherwise leaves "call: strerror", so a failing call
// never shows an older call's text.
#include <cerrno>
#include <cstdarg>
#include <cstdio>
#include <cstring>

#include "err/err_internal.hpp"

namespace chm::kernel {

bool err_kernel_thread();  // err/fault.cpp

namespace {

thread_local LastError t_last;

// The caller's record: its task's (allocated with the task's error state
// on first use), else the thread's. A task whose error state cannot be
// allocated uses the thread's: the text may then be another task's.
LastError& here() {
    if (err_kernel_thread() && g_k.current && !g_k.in_irq) {
        if (ErrTask* e = err_task(g_k.current, true)) return e->last;
    }
    return t_last;
}

}  // namespace

void err_last_set(const char* text) {
    LastError& l = here();
    std::size_t n = std::strlen(text);
    if (n >= sizeof l.text) n = sizeof l.text - 1;
    std::memmove(l.text, text, n);  // text may be l.text itself
    l.text[n] = 0;
    l.fresh = true;
    l.call = nullptr;
}

// Only noted here (a failing try in a polling loop pays three stores); the
// text is made when someone asks for it.
void err_last_failed(const char* call, int status, bool keep_set) {
    LastError& l = here();
    if (!(keep_set && l.fresh && l.text[0])) {
        l.call = call ? call : "chimera";
        l.status = status;
    }
    l.fresh = false;
}

}  // namespace chm::kernel

extern "C" {

const char* chm_err_last(void) {
    chm::kernel::LastError& l = chm::kernel::here();
    if (l.call) {
        std::snprintf(l.text, sizeof l.text, "%s: %s", l.call, std::strerror(-l.status));
        l.call = nullptr;
    }
    return l.text;
}

void chm_err_set_last(const char* fmt, ...) {
    if (!fmt) return;
    char buf[CHM_ERR_LAST_MAX];
    va_list ap;
    va_start(ap, fmt);
    std::vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    chm::kernel::err_last_set(buf);
}

}  // extern "C"
