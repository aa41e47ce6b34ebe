// Simulated devices: creating, mapping and locking the shared-state files,
// their directory, and the FIFO that carries a device's interrupt line.
#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <new>

#include "chimera/irq.h"
#include "simfile.hpp"

namespace chm::sim {

std::uint64_t mono_ns() {
    timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return std::uint64_t(ts.tv_sec) * 1000000000u + std::uint64_t(ts.tv_nsec);
}

std::int32_t to_code(double v, double vmin, double vmax, std::uint32_t bits) {
    const double top = double((1u << bits) - 1);
    double c = std::nearbyint((v - vmin) / (vmax - vmin) * top);
    if (!(c >= 0)) c = 0;  // NaN too
    if (c > top) c = top;
    return std::int32_t(c);
}

double from_code(std::int32_t code, double vmin, double vmax, std::uint32_t bits) {
    const double top = double((1u << bits) - 1);
    return vmin + double(code) * (vmax - vmin) / top;
}

static int fifo_path(const char* path, char* out, std::size_t cap) {
    const int n = std::snprintf(out, cap, "%s.irq", path);
    return n < 0 || std::size_t(n) >= cap ? -ENAMETOOLONG : 0;
}

int file_create(const char* path, chm_sim_kind kind, const void* init, std::size_t bytes,
                std::size_t file_size) {
    char tmp[CHM_SIM_PATH_MAX + 32], fifo[CHM_SIM_PATH_MAX + 8];
    if (std::snprintf(tmp, sizeof tmp, "%s.new.%d", path, int(getpid())) >= int(sizeof tmp))
        return -ENAMETOOLONG;
    if (int r = fifo_path(path, fifo, sizeof fifo); r < 0) return r;
    const int fd = open(tmp, O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
    if (fd < 0) return -errno;
    int r = ftruncate(fd, off_t(file_size)) == 0 ? 0 : -errno;
    void* base = r == 0 ? mmap(nullptr, file_size, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0) : MAP_FAILED;
    if (r == 0 && base == MAP_FAILED) r = -errno;
    if (r == 0) {
        std::memcpy(base, init, bytes);
        auto* h = static_cast<Header*>(base);
        h->magic = kMagic;
        h->version = kVersion;
        h->kind = std::uint16_t(kind);
        h->size = std::uint32_t(file_size);
        h->seq = 0;
        pthread_mutexattr_t a;
        pthread_mutexattr_init(&a);
        pthread_mutexattr_setpshared(&a, PTHREAD_PROCESS_SHARED);
        pthread_mutexattr_setrobust(&a, PTHREAD_MUTEX_ROBUST);
        pthread_mutex_init(&h->mu, &a);
        pthread_mutexattr_destroy(&a);
        munmap(base, file_size);
        if (mkfifo(fifo, 0600) != 0 && errno != EEXIST) r = -errno;
    }
    close(fd);
    if (r == 0 && link(tmp, path) != 0) r = -errno;  // atomic publish; EEXIST if taken
    unlink(tmp);
    return r;
}

// Through the public calls, not the port's inline mask: a module that
// carries this code (the arm demo's arm_io) then refers to functions only,
// which a lazy dlopen (chimera svar plan) leaves unresolved.
Locked::Locked(chm_sim_t* s) : s_(s) {
    chm_irq_lock();  // never preempted (nor interrupted) holding the file's lock
    if (pthread_mutex_lock(&header(s)->mu) == EOWNERDEAD) pthread_mutex_consistent(&header(s)->mu);
}

Locked::~Locked() {
    pthread_mutex_unlock(&header(s_)->mu);
    chm_irq_unlock();
}

void raise_line(chm_sim_t* s) {
    if (s->irq_fd < 0) return;
    const char b = 1;
    (void)!write(s->irq_fd, &b, 1);
}

}  // namespace chm::sim

using namespace chm::sim;

extern "C" {

const char* chm_sim_dir(void) {
    static char dir[CHM_SIM_PATH_MAX];
    const char* env = std::getenv("CHIMERA_SIM_DIR");
    if (env && *env) {
        std::snprintf(dir, sizeof dir, "%s", env);
    } else {
        std::snprintf(dir, sizeof dir, "/dev/shm/chimera-sim-%u", unsigned(getuid()));
    }
    mkdir(dir, 0700);
    return dir;
}

int chm_sim_path(const char* name, char* out, size_t cap) {
    if (!name || !*name || !out) return -EINVAL;
    const int n = std::strchr(name, '/') ? std::snprintf(out, cap, "%s", name)
                                         : std::snprintf(out, cap, "%s/%s", chm_sim_dir(), name);
    return n < 0 || std::size_t(n) >= cap || std::size_t(n) >= CHM_SIM_PATH_MAX ? -ENAMETOOLONG : 0;
}

int chm_sim_attach(const char* path, chm_sim_t** out) {
    if (!path || !out) return -EINVAL;
    if (std::strlen(path) >= CHM_SIM_PATH_MAX) return -ENAMETOOLONG;
    const int fd = open(path, O_RDWR | O_CLOEXEC);
    if (fd < 0) return -errno;
    struct stat sb;
    if (fstat(fd, &sb) != 0 || std::size_t(sb.st_size) < sizeof(Header)) {
        close(fd);
        return -EPROTO;
    }
    const std::size_t size = std::size_t(sb.st_size);
    void* base = mmap(nullptr, size, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
    if (base == MAP_FAILED) {
        const int e = errno;
        close(fd);
        return -e;
    }
    const auto* h = static_cast<const Header*>(base);
    if (h->magic != kMagic || h->version != kVersion || h->size != size || h->kind < CHM_SIM_ARM ||
        h->kind > CHM_SIM_SERIAL) {
        munmap(base, size);
        close(fd);
        return -EPROTO;
    }
    auto* s = new (std::nothrow) chm_sim;
    if (!s) {
        munmap(base, size);
        close(fd);
        return -ENOMEM;
    }
    s->fd = fd;
    s->base = base;
    s->size = size;
    std::snprintf(s->path, sizeof s->path, "%s", path);
    char fifo[CHM_SIM_PATH_MAX + 8];
    if (fifo_path(path, fifo, sizeof fifo) == 0)
        s->irq_fd = open(fifo, O_RDWR | O_NONBLOCK | O_CLOEXEC);  // O_RDWR: never ENXIO, never SIGPIPE
    *out = s;
    return 0;
}

void chm_sim_detach(chm_sim_t* s) {
    if (!s) return;
    munmap(s->base, s->size);
    close(s->fd);
    if (s->irq_fd >= 0) close(s->irq_fd);
    delete s;
}

enum chm_sim_kind chm_sim_kind_of(const chm_sim_t* s) {
    return chm_sim_kind(static_cast<const Header*>(s->base)->kind);
}

uint64_t chm_sim_seq(const chm_sim_t* s) {
    return __atomic_load_n(&static_cast<const Header*>(s->base)->seq, __ATOMIC_ACQUIRE);
}

int chm_sim_remove(const char* path) {
    if (!path) return -EINVAL;
    char fifo[CHM_SIM_PATH_MAX + 8], pty[CHM_SIM_PATH_MAX + 8];
    if (fifo_path(path, fifo, sizeof fifo) == 0) unlink(fifo);
    std::snprintf(pty, sizeof pty, "%s.pty", path);
    unlink(pty);
    return unlink(path) == 0 ? 0 : -errno;
}

}  // extern "C"
