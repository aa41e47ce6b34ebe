// Device drivers: the one place where a failing device call is reported.
//
// Every refusal of level 1 and level 2 goes through fail(): it records a
// message naming the call, the device and the problem for
// chm_dev_last_error(). When the global error layer (issue 5, items 1-2)
// lands, fail() is where it raises the error signal of module "dev"; until
// then callers get the documented negative status.
#include <cstdio>
#include <cstring>

#include "kernel/dev/dev.hpp"
#include "chimera/sensor.h"

namespace chm::dev {
namespace {
thread_local char t_last[256];
}

int fail(int status, const char* call, const char* fmt, ...) {
    const int k = std::snprintf(t_last, sizeof t_last, "%s: ", call);
    va_list ap;
    va_start(ap, fmt);
    if (k > 0 && std::size_t(k) < sizeof t_last)
        std::vsnprintf(t_last + k, sizeof t_last - std::size_t(k), fmt, ap);
    va_end(ap);
    return status;
}

}  // namespace chm::dev

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
