// Host procedure calls (chimera/host.h): chdir, getcwd, getenv and run,
// each one request to the host server (client.hpp).
#include <cerrno>
#include <cstring>

#include "chimera/host.h"
#include "chimera/xfs.h"
#include "host/client.hpp"

using namespace chm::host;

extern "C" {

int chm_host_chdir(const char* path) {
    clear_error();
    if (!path) return set_error("chdir: NULL path"), -EINVAL;
    char what[160];
    std::snprintf(what, sizeof what, "chdir %s", path);
    HostRequest h{};
    h.op = kChdir;
    return request(h, path, std::uint32_t(std::strlen(path) + 1), nullptr, 0, nullptr, what);
}

int chm_host_getcwd(char* buf, size_t len) {
    clear_error();
    if (!buf || !len) return set_error("getcwd: no buffer"), -EINVAL;
    HostRequest h{};
    h.op = kGetcwd;
    char reply[2048];
    std::uint32_t n = 0;
    const int r = request(h, nullptr, 0, reply, sizeof reply - 1, &n, "getcwd");
    if (r < 0) return r;
    reply[n < sizeof reply ? n : sizeof reply - 1] = 0;
    const std::size_t k = std::strlen(reply);
    if (k + 1 > len) return set_error("getcwd: %zu bytes do not fit %zu", k + 1, len), -ERANGE;
    std::memcpy(buf, reply, k + 1);
    return 0;
}

int chm_host_getenv(const char* name, char* buf, size_t len) {
    clear_error();
    if (!name || !*name || std::strchr(name, '='))
        return set_error("getenv: bad name \"%s\"", name ? name : "(null)"), -EINVAL;
    if (!buf || !len) return set_error("getenv %s: no buffer", name), -EINVAL;
    char what[96];
    std::snprintf(what, sizeof what, "getenv %s", name);
    HostRequest h{};
    h.op = kGetenv;
    char reply[2048];
    std::uint32_t n = 0;
    const int r = request(h, name, std::uint32_t(std::strlen(name) + 1), reply, sizeof reply - 1, &n, what);
    if (r < 0) return r;
    reply[n < sizeof reply ? n : sizeof reply - 1] = 0;
    const std::size_t k = std::strlen(reply);
    if (k + 1 > len) return set_error("%s: %zu bytes do not fit %zu", what, k + 1, len), -ERANGE;
    std::memcpy(buf, reply, k + 1);
    return int(k);
}

int chm_host_run(int argc, const char* const* argv, int* status) {
    clear_error();
    if (argc < 1 || !argv || !argv[0] || !*argv[0]) return set_error("run: no program"), -EINVAL;
    char text[2048];
    std::size_t off = 0;
    for (int i = 0; i < argc; ++i) {
        const char* s = argv[i] ? argv[i] : "";
        const std::size_t k = std::strlen(s) + 1;
        if (off + k > sizeof text || off + k > inline_room())
            return set_error("run %s: the argument vector does not fit one request", argv[0]), -E2BIG;
        std::memcpy(text + off, s, k);
        off += k;
    }
    char what[160];
    std::snprintf(what, sizeof what, "run %s", argv[0]);
    HostRequest h{};
    h.op = kRun;
    h.a = std::uint64_t(argc);
    // However long the program runs: the sender still sees a dead host
    // server within one 20 ms slice.
    const int r = request(h, text, std::uint32_t(off), nullptr, 0, nullptr, what, UINT64_MAX / 4);
    if (r < 0) return r;
    if (status) *status = r;
    return 0;
}

}  // extern "C"
