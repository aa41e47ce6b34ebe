#include "realtime.hpp"

#include <cerrno>
#include <cstdlib>
#include <cstring>

#include <linux/capability.h>
#include <sched.h>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <sys/syscall.h>
#include <unistd.h>

#include "../parse_num.hpp"

namespace chimera_rtpu {
namespace {

std::string os_error(const std::string& what, int err, const char* hint = "") {
    return what + ": " + std::strerror(err) + hint;
}

}  // namespace

std::string parse_fifo_priority(const char* s, int* out) {
    const long hi = sched_get_priority_max(SCHED_FIFO);
    long v = 0;
    if (!chimera_tools::parse_num(s, 1, hi, &v))
        return "--rt-priority wants a SCHED_FIFO priority 1.." + std::to_string(hi) + ", not \"" + s + "\"";
    *out = int(v);
    return "";
}

std::string parse_cpu(const char* s, int* out) {
    long v = 0;
    if (!chimera_tools::parse_num(s, 0, CPU_SETSIZE - 1, &v)) return std::string("--cpu wants a CPU number, not \"") + s + "\"";
    cpu_set_t allowed;
    CPU_ZERO(&allowed);
    if (sched_getaffinity(0, sizeof allowed, &allowed) == 0 && !CPU_ISSET(int(v), &allowed))
        return "--cpu " + std::to_string(v) + ": this process may not run on that CPU (" +
               std::to_string(CPU_COUNT(&allowed)) + " allowed)";
    *out = int(v);
    return "";
}

std::string apply(const HostRealtime& rt) {
    if (rt.cpu >= 0) {
        cpu_set_t one;
        CPU_ZERO(&one);
        CPU_SET(rt.cpu, &one);
        if (sched_setaffinity(0, sizeof one, &one) != 0)
            return os_error("--cpu " + std::to_string(rt.cpu) + ": sched_setaffinity", errno);
    }
    if (rt.lock_memory && mlockall(MCL_CURRENT | MCL_FUTURE) != 0)
        return os_error("--lock-memory: mlockall", errno,
                        errno == ENOMEM || errno == EPERM ? " (needs CAP_IPC_LOCK or a higher memlock limit)" : "");
    if (rt.fifo_priority > 0) {
        sched_param sp{};
        sp.sched_priority = rt.fifo_priority;
        if (sched_setscheduler(0, SCHED_FIFO, &sp) != 0)
            return os_error("--rt-priority " + std::to_string(rt.fifo_priority) + ": sched_setscheduler(SCHED_FIFO)",
                            errno, errno == EPERM ? " (needs CAP_SYS_NICE or an rtprio limit: ulimit -r)" : "");
    }
    return "";
}

std::string drop_privileges(const HostRealtime& rt) {
    // capget/capset directly: libcap is not needed for this.
    __user_cap_header_struct hdr{_LINUX_CAPABILITY_VERSION_3, 0};
    __user_cap_data_struct data[_LINUX_CAPABILITY_U32S_3] = {};
    if (::syscall(SYS_capget, &hdr, data) != 0) return os_error("capget", errno);
    const unsigned keep = CAP_IPC_LOCK;
    const bool keep_lock = rt.lock_memory && (data[keep / 32].permitted & (1u << (keep % 32)));
    bool any = false;
    for (auto& d : data) {
        any = any || d.permitted || d.effective || d.inheritable;
        d.permitted = d.effective = d.inheritable = 0;
    }
    (void)::prctl(PR_CAP_AMBIENT, PR_CAP_AMBIENT_CLEAR_ALL, 0, 0, 0);  // EINVAL before Linux 4.3: none then
    if (!any) return "";
    if (keep_lock) {
        data[keep / 32].permitted = 1u << (keep % 32);
        data[keep / 32].effective = 1u << (keep % 32);
    }
    if (::syscall(SYS_capset, &hdr, data) != 0) return os_error("capset (dropping capabilities)", errno);
    (void)::prctl(PR_SET_DUMPABLE, 1, 0, 0, 0);
    return "";
}

}  // namespace chimera_rtpu
