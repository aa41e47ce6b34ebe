// Module "ipc" of global error handling (see report.hpp): registered on
// first use with its code table; raised in the failing task's context with
// the backplane's message for the call (chm_bp_last_error) as the detail.
#include "ipc/err/report.hpp"

#include <pthread.h>

#include <cerrno>
#include <cstring>

#include "chimera/bp.h"
#include "chimera/err.h"
#include "kernel/err/err_internal.hpp"

namespace chm::ipc {
namespace {

// What raises. Missing: the outcomes ETIMEDOUT, EAGAIN (full, empty, taken),
// EINTR, EOWNERDEAD, EIDRM, EOVERFLOW (a V past the count's limit, as for
// the kernel's semaphores), and EBUSY / EDEADLK (in use, or an internal
// lock held past its bound by a live peer: retry later), which a control
// program handles where it calls.
const chm_err_code_t kCodes[] = {
    {EINVAL, "invalid argument (NULL, not a handle of that kind, bad attribute)"},
    {ENOENT, "no object of that name and kind"},
    {ENOTCONN, "not attached to a backplane"},
    {ECHRNG, "placement is neither common memory nor an RTPU of the backplane"},
    {EEXIST, "name already taken"},
    {ENAMETOOLONG, "name too long"},
    {ENOMEM, "no room in that memory"},
    {ENOSPC, "table full (registry, waiter records)"},
    {EMSGSIZE, "message larger than the queue's message size"},
    {EPERM, "not permitted (not the holder, interrupt context)"},
    {ESRCH, "no such task or RTPU"},
    {EBADMSG, "corrupt object or backplane file"},
    {ENOTRECOVERABLE, "object corrupt and marked unusable"},
    {EBADF, "bad descriptor"},
    {EFAULT, "bad address"},
};

bool raises(int status) {
    for (const auto& c : kCodes)
        if (c.code == -status) return true;
    return false;
}

pthread_once_t g_once = PTHREAD_ONCE_INIT;
int g_module = -1;

void register_module() {
    int m = chm_err_module_register("ipc", kCodes, sizeof kCodes / sizeof kCodes[0]);
    if (m == -EEXIST) m = chm_err_module_find("ipc");
    g_module = m;
}

}  // namespace

int leave_failed(int status, const char* call) {
    // chm_err_last: the backplane's message when this call set one (an
    // error, not an outcome such as a full queue), else "call: strerror".
    kernel::err_last_failed(call, status, raises(status));
    // Host threads and tasks without global handling: a status, as always.
    // Never under the mask (interrupt context or a kernel path).
    if (!raises(status) || !chm_err_global_get() || port::irq_masked()) return status;
    pthread_once(&g_once, register_module);
    if (g_module <= 0) return status;
    chm_err_info_t info{};
    info.module = g_module;
    info.code = -status;
    info.call = call;
    // The backplane's message names the object and the problem; only when
    // it is this call's (a call that failed without one leaves an older
    // message behind).
    const char* why = chm_bp_last_error();
    const std::size_t n = std::strlen(call);
    // The line names the call already: keep what follows "call: " or
    // "call " (a message that names the object next).
    if (why && std::strncmp(why, call, n) == 0 && (why[n] == ':' || why[n] == ' '))
        info.detail = why + n + (why[n] == ':' && why[n + 1] == ' ' ? 2 : 1);
    info.status = status;
    const int saved = errno;
    kernel::err_raise(info);  // returns when a handler continues
    errno = saved;
    return status;
}

}  // namespace chm::ipc

extern "C" int chm_ipc_err_module(void) {
    pthread_once(&chm::ipc::g_once, chm::ipc::register_module);
    return chm::ipc::g_module;
}
