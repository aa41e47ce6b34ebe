// The UNIX calls a control program uses, wrapped for global error
// handling: with it on, a failure is a "unix" error signal (code errno)
// instead of a -1 or NULL to check. With it off, or outside a task, they
// are the libc calls themselves.
#include <cerrno>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <fcntl.h>
#include <sys/ioctl.h>
#include <unistd.h>

#include "chimera/mem.h"
#include "err/err_internal.hpp"

namespace chm::kernel {
bool err_kernel_thread();
}

using namespace chm::kernel;

namespace {

// The failure path: errno is what the call set, and stays so.
void failed(const char* call, const char* detail) {
    {
        const int e = errno;
        char text[CHM_ERR_LAST_MAX];
        std::snprintf(text, sizeof text, "%s%s%s: %s", call, detail ? " " : "", detail ? detail : "",
                      std::strerror(e));
        err_last_set(text);  // chm_err_last
        errno = e;
    }
    if (!err_kernel_thread()) return;
    Tcb* cur = g_k.current;
    if (!cur || !cur->err || !cur->err->global) return;
    const int e = errno;
    chm_err_info_t info{};
    info.module = CHM_ERR_UNIX;
    info.code = e;
    info.call = call;
    info.detail = detail;
    info.status = -1;
    err_raise(info);
    errno = e;
}

}  // namespace

extern "C" {

int chm_unix_open(const char* path, int flags, ...) {
    mode_t mode = 0;
    if (flags & (O_CREAT | O_TMPFILE)) {
        va_list ap;
        va_start(ap, flags);
        mode = mode_t(va_arg(ap, unsigned));
        va_end(ap);
    }
    const int fd = open(path, flags, mode);
    if (fd < 0) [[unlikely]] failed("open", path);
    return fd;
}

int chm_unix_close(int fd) {
    const int r = close(fd);
    if (r < 0) [[unlikely]] failed("close", nullptr);
    return r;
}

ssize_t chm_unix_read(int fd, void* buf, size_t n) {
    const ssize_t r = read(fd, buf, n);
    if (r < 0) [[unlikely]] failed("read", nullptr);
    return r;
}

ssize_t chm_unix_write(int fd, const void* buf, size_t n) {
    const ssize_t r = write(fd, buf, n);
    if (r < 0) [[unlikely]] failed("write", nullptr);
    return r;
}

off_t chm_unix_lseek(int fd, off_t off, int whence) {
    const off_t r = lseek(fd, off, whence);
    if (r < 0) [[unlikely]] failed("lseek", nullptr);
    return r;
}

int chm_unix_ioctl(int fd, unsigned long request, ...) {
    va_list ap;
    va_start(ap, request);
    void* arg = va_arg(ap, void*);
    va_end(ap);
    const int r = ioctl(fd, request, arg);
    if (r < 0) [[unlikely]] failed("ioctl", nullptr);
    return r;
}

void* chm_unix_malloc(size_t size) {
    void* p = chm_malloc(size);
    if (!p) [[unlikely]] failed("malloc", nullptr);
    return p;
}

// The names before API 1.0, kept for one release (CHANGELOG.md): the same
// functions under a second symbol.
int chm_open(const char* path, int flags, ...) __attribute__((alias("chm_unix_open")));
int chm_close(int fd) __attribute__((alias("chm_unix_close")));
ssize_t chm_read(int fd, void* buf, size_t n) __attribute__((alias("chm_unix_read")));
ssize_t chm_write(int fd, const void* buf, size_t n) __attribute__((alias("chm_unix_write")));
off_t chm_lseek(int fd, off_t off, int whence) __attribute__((alias("chm_unix_lseek")));
int chm_ioctl(int fd, unsigned long request, ...) __attribute__((alias("chm_unix_ioctl")));
void* chm_malloc_checked(size_t size) __attribute__((alias("chm_unix_malloc")));

}  // extern "C"
