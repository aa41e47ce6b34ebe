// The monotonic clock of every POSIX port (vDSO clock_gettime: no syscall).
#include "port.hpp"

#include <ctime>

namespace chm::port {

std::uint64_t now_ns() {
    timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return std::uint64_t(ts.tv_sec) * 1000000000u + std::uint64_t(ts.tv_nsec);
}

}  // namespace chm::port
