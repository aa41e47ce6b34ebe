// Buffered stdio over the extended file system (chm_xfs_fopen): a glibc
// fopencookie FILE whose read, write, seek and close are chm_xfs_* calls.
#include <cerrno>
#include <cstring>

#include "chimera/xfs.h"
#include "host/client.hpp"

namespace {

int handle_of(void* cookie) { return int(reinterpret_cast<std::intptr_t>(cookie)); }

ssize_t cookie_read(void* c, char* buf, size_t n) {
    const std::int64_t r = chm_xfs_read(handle_of(c), buf, n);
    if (r < 0) {
        errno = int(-r);
        return -1;
    }
    return ssize_t(r);
}

ssize_t cookie_write(void* c, const char* buf, size_t n) {
    const std::int64_t r = chm_xfs_write(handle_of(c), buf, n);
    if (r < 0) {
        errno = int(-r);
        return 0;  // fopencookie: 0 is the error return of a write
    }
    return ssize_t(r);
}

int cookie_seek(void* c, off64_t* pos, int whence) {
    const std::int64_t r = chm_xfs_lseek(handle_of(c), *pos, whence);
    if (r < 0) {
        errno = int(-r);
        return -1;
    }
    *pos = r;
    return 0;
}

int cookie_close(void* c) {
    const int r = chm_xfs_close(handle_of(c));
    if (r < 0) {
        errno = -r;
        return -1;
    }
    return 0;
}

}  // namespace

extern "C" FILE* chm_xfs_fopen(const char* path, const char* mode) {
    chm::host::clear_error();
    if (!mode || !*mode) {
        chm::host::set_error("fopen %s: empty mode", path ? path : "(null)");
        errno = EINVAL;
        return nullptr;
    }
    const bool plus = std::strchr(mode, '+') != nullptr;
    int flags;
    switch (mode[0]) {
    case 'r': flags = plus ? CHM_XFS_RDWR : CHM_XFS_RDONLY; break;
    case 'w': flags = (plus ? CHM_XFS_RDWR : CHM_XFS_WRONLY) | CHM_XFS_CREAT | CHM_XFS_TRUNC; break;
    case 'a': flags = (plus ? CHM_XFS_RDWR : CHM_XFS_WRONLY) | CHM_XFS_CREAT | CHM_XFS_APPEND; break;
    default:
        chm::host::set_error("fopen %s: mode \"%s\" is not r, w or a (with +)", path ? path : "(null)", mode);
        errno = EINVAL;
        return nullptr;
    }
    if (std::strchr(mode, 'x')) flags |= CHM_XFS_EXCL;
    const int fd = chm_xfs_open(path, flags, 0666);
    if (fd < 0) {
        errno = -fd;
        return nullptr;
    }
    cookie_io_functions_t io{cookie_read, cookie_write, cookie_seek, cookie_close};
    FILE* f = fopencookie(reinterpret_cast<void*>(std::intptr_t(fd)), mode, io);
    if (!f) {
        const int e = errno;
        chm::host::set_error("fopen %s: %s", path, std::strerror(e));
        (void)chm_xfs_close(fd);
        errno = e;
    }
    return f;
}
