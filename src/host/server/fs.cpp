// Paths beneath the host server's root. openat2(RESOLVE_BENEATH) refuses
// every way out (absolute paths, "..", absolute or escaping symbolic links,
// /proc magic links) inside the kernel, atomically. Where the kernel has no
// openat2 (before Linux 5.6, or an emulator), the directory is opened and
// its real path checked before the last component is opened with
// O_NOFOLLOW, and the result checked again: nothing is created outside.
#include <cerrno>
#include <climits>
#include <cstdlib>
#include <cstring>

#include <fcntl.h>
#include <linux/openat2.h>
#include <sys/vfs.h>
#include <sys/syscall.h>
#include <unistd.h>

#include "host/server/server.hpp"

namespace chm::host::server {

namespace {

int g_root_fd = -1;
std::string g_root;  // its real path, no trailing '/'

int fd_path(int fd, std::string* out) {
    char link[64], buf[PATH_MAX];
    std::snprintf(link, sizeof link, "/proc/self/fd/%d", fd);
    const ssize_t n = ::readlink(link, buf, sizeof buf - 1);
    if (n < 0) return -errno;
    out->assign(buf, std::size_t(n));
    return 0;
}

bool beneath(const std::string& p) {
    if (p == g_root) return true;
    if (g_root == "/") return true;
    return p.size() > g_root.size() && p.compare(0, g_root.size(), g_root) == 0 && p[g_root.size()] == '/';
}

// The fallback: parent directory checked, then the last component.
int open_checked(const std::string& rel, int oflags, unsigned mode, const char** why) {
    const std::size_t slash = rel.rfind('/');
    const std::string dir = slash == std::string::npos ? "." : rel.substr(0, slash ? slash : 1);
    const std::string base = slash == std::string::npos ? rel : rel.substr(slash + 1);
    const int dfd = ::openat(g_root_fd, dir.c_str(), O_PATH | O_DIRECTORY | O_CLOEXEC);
    if (dfd < 0) return -errno;
    std::string real;
    if (fd_path(dfd, &real) != 0 || !beneath(real)) {
        ::close(dfd);
        *why = "leads out of the host root";
        return -EXDEV;
    }
    const int fd = ::openat(dfd, base.empty() ? "." : base.c_str(), oflags | O_NOFOLLOW | O_CLOEXEC, mode);
    const int e = errno;
    ::close(dfd);
    if (fd < 0) {
        if (e == ELOOP) *why = "is a symbolic link (not followed without openat2)";
        return -e;
    }
    if (fd_path(fd, &real) != 0 || !beneath(real)) {
        ::close(fd);
        *why = "leads out of the host root";
        return -EXDEV;
    }
    return fd;
}

}  // namespace

int fs_init(const char* root) {
    char real[PATH_MAX];
    if (!::realpath(root, real)) return -errno;
    const int fd = ::open(real, O_PATH | O_DIRECTORY | O_CLOEXEC);
    if (fd < 0) return -errno;
    g_root_fd = fd;
    g_root = real;
    return 0;
}

void fs_fini() {
    if (g_root_fd >= 0) ::close(g_root_fd);
    g_root_fd = -1;
}

const std::string& fs_root() { return g_root; }

int fs_join(const Client& c, const char* path, std::string* out, const char** why) {
    if (path[0] == '/') {
        *why = "is absolute (paths are relative to the host root)";
        return -EXDEV;
    }
    if (c.cwd.empty())
        *out = *path ? path : ".";
    else
        *out = *path ? c.cwd + "/" + path : c.cwd;
    return 0;
}

int fs_open(const std::string& rel, int oflags, unsigned mode, const char** why) {
    open_how how{};
    how.flags = std::uint64_t(oflags | O_CLOEXEC);
    how.mode = (oflags & O_CREAT) ? mode : 0;
    how.resolve = RESOLVE_BENEATH | RESOLVE_NO_MAGICLINKS;
    const long fd = ::syscall(SYS_openat2, g_root_fd, rel.c_str(), &how, sizeof how);
    if (fd >= 0) return int(fd);
    const int e = errno;
    if (e == ENOSYS) return open_checked(rel, oflags, mode, why);
    if (e == EXDEV) *why = "leads out of the host root";
    return -e;
}

int fs_relative(int fd, std::string* out) {
    std::string real;
    if (int e = fd_path(fd, &real)) return e;
    if (!beneath(real)) return -EXDEV;
    *out = real.size() > g_root.size() ? real.substr(g_root.size() + (g_root == "/" ? 0 : 1)) : "";
    return 0;
}

bool fs_local(int fd) {
    struct statfs f {};
    if (::fstatfs(fd, &f) != 0) return false;
    switch (static_cast<unsigned long>(f.f_type)) {
    case 0xEF53:      // ext2, ext3, ext4
    case 0x58465342:  // xfs
    case 0x9123683E:  // btrfs
    case 0xF2F52010:  // f2fs
    case 0x01021994:  // tmpfs
    case 0x794C7630:  // overlayfs
        return true;
    default:
        return false;
    }
}

}  // namespace chm::host::server
