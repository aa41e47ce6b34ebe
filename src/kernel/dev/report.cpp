// Device drivers: the one place where a failing device call is reported.
//
// Every refusal of level 1 and level 2 goes through fail(): it records a
// message naming the call, the device and the problem for
// chm_dev_last_error(). Every public call leaves through leave(): when the
// calling task has global error handling on (chimera/err.h), a failure
// fail() recorded becomes an error signal of module "dev" (code = the errno
// value, detail = that message), raised there because by then the call
// holds no lock and no pinned descriptor, so a handler may abort the task
// or jump to a mark safely.
#include <pthread.h>

#include <cstdio>
#include <cstring>

#include "chimera/err.h"
#include "chimera/sensor.h"
#include "kernel/dev/dev.hpp"
#include "kernel/err/err_internal.hpp"

namespace chm::dev {
namespace {
thread_local char t_last[256];
thread_local const char* t_call = nullptr;
thread_local int t_status = 0;
thread_local int t_detail = 0;  // where the message starts after "call: "

const chm_err_code_t kCodes[] = {
    {ENODEV, "no such device"},
    {EBADF, "descriptor not open (closed, stale or never issued)"},
    {ENOTTY, "unknown ioctl request"},
    {ENXIO, "offset past the end of the device's range"},
    {EOPNOTSUPP, "operation not supported by the device"},
    {EACCES, "not opened for that direction, or read-only register"},
    {EEXIST, "device name already registered"},
    {EBUSY, "device has open descriptors"},
    {EMFILE, "descriptor table full"},
    {EINVAL, "invalid argument"},
    {ERANGE, "command beyond the actuator's limits (refused)"},
    {ESHUTDOWN, "actuator in safe stop (resume first)"},
    {ENAMETOOLONG, "device name too long"},
    {ENOSPC, "table full"},
    {ENOMEM, "out of memory"},
};
pthread_once_t g_once = PTHREAD_ONCE_INIT;
int g_module = -1;

void register_module() {
    int m = chm_err_module_register("dev", kCodes, sizeof kCodes / sizeof kCodes[0]);
    if (m == -EEXIST) m = chm_err_module_find("dev");
    g_module = m;
}

bool outcome(int status) { return status == -EAGAIN || status == -ETIMEDOUT || status == -EINTR; }
}  // namespace

int fail(int status, const char* call, const char* fmt, ...) {
    t_call = call;
    t_status = status;
    const int k = std::snprintf(t_last, sizeof t_last, "%s: ", call);
    t_detail = k > 0 && std::size_t(k) < sizeof t_last ? k : 0;
    va_list ap;
    va_start(ap, fmt);
    if (k > 0 && std::size_t(k) < sizeof t_last)
        std::vsnprintf(t_last + k, sizeof t_last - std::size_t(k), fmt, ap);
    va_end(ap);
    kernel::err_last_set(t_last);  // chm_err_last
    return status;
}

int64_t leave(int64_t status) {
    if (status >= 0 || status != t_status || outcome(int(status))) return status;
    if (!chm_err_global_get() || port::irq_masked()) return status;
    pthread_once(&g_once, register_module);
    if (g_module <= 0) return status;
    t_status = 0;  // raised once
    chm_err_info_t info{};
    info.module = g_module;
    info.code = int(-status);
    info.call = t_call;
    info.detail = t_last + t_detail;  // the call is named in info.call
    info.status = int(status);
    kernel::err_raise(info);  // returns when a handler continues
    return status;
}

}  // namespace chm::dev

extern "C" int chm_dev_err_module(void) {
    pthread_once(&chm::dev::g_once, chm::dev::register_module);
    return chm::dev::g_module;
}

extern "C" const char* chm_dev_last_error(void) { return chm::dev::t_last; }

extern "C" const char* chm_dev_strerror(int status) {
    switch (status) {
    case 0: return "success";
    case CHM_ACT_CLAMPED: return "command clamped into the actuator's limits";
    case CHM_EDEV_NODEV: return "no such device";
    case CHM_EDEV_BADF: return "descriptor not open (closed, stale or never issued)";
    case CHM_EDEV_NOTTY: return "unknown ioctl request";
    case CHM_EDEV_RANGE: return "offset past the end of the device's range";
    case CHM_EDEV_NOTSUP: return "operation not supported by the device";
    case CHM_EDEV_ACCES: return "not opened for that direction, or read-only register";
    case CHM_EDEV_EXIST: return "device name already registered";
    case CHM_EDEV_BUSY: return "device has open descriptors";
    case CHM_EDEV_MFILE: return "descriptor table full";
    case CHM_EDEV_INVAL: return "invalid argument";
    case CHM_EACT_LIMIT: return "command beyond the actuator's limits (refused)";
    case CHM_EACT_STOPPED: return "actuator in safe stop (resume first)";
    default: return status < 0 ? std::strerror(-status) : "positive status";
    }
}
