// Simulated serial port on a pseudo-terminal. The RTPU that registers the
// device holds the master side; the other end (the "line") is a /dev/pts
// name published in the device's file and as the symlink "<file>.pty", so a
// test, `screen` or any program can talk to it. Line settings are the
// slave's termios (what the peer sees); the port starts raw, 115200 8N1.
// A Linux pty keeps 8 data bits without parity whatever is asked (its
// driver rewrites them): the speed, stop bits and flow control reach the
// peer's termios, and GET_LINE reports the settings as configured.
// A stream device: level 1 only (read, write, ioctl).
#include <fcntl.h>
#include <poll.h>
#include <stdlib.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>

#include "drivers.hpp"

namespace chm::sim {
namespace {

struct Speed {
    std::uint32_t baud;
    speed_t code;
};
const Speed kSpeeds[] = {
    {50, B50}, {75, B75}, {110, B110}, {134, B134}, {150, B150}, {200, B200}, {300, B300},
    {600, B600}, {1200, B1200}, {1800, B1800}, {2400, B2400}, {4800, B4800}, {9600, B9600},
    {19200, B19200}, {38400, B38400}, {57600, B57600}, {115200, B115200}, {230400, B230400},
    {460800, B460800}, {500000, B500000}, {576000, B576000}, {921600, B921600},
    {1000000, B1000000}, {1500000, B1500000}, {2000000, B2000000}, {3000000, B3000000},
    {4000000, B4000000},
};

int set_line(int fd, const chm_serial_line_t& l) {
    speed_t sp = 0;
    bool found = false;
    for (const Speed& s : kSpeeds)
        if (s.baud == l.baud) { sp = s.code; found = true; }
    if (!found || l.data_bits < 5 || l.data_bits > 8 || (l.parity != 'N' && l.parity != 'E' && l.parity != 'O') ||
        (l.stop_bits != 1 && l.stop_bits != 2) || l.rtscts > 1)
        return CHM_EDEV_INVAL;
    termios t;
    if (tcgetattr(fd, &t) != 0) return -errno;
    cfmakeraw(&t);
    t.c_cflag &= ~tcflag_t(CSIZE | PARENB | PARODD | CSTOPB | CRTSCTS);
    static const tcflag_t sizes[] = {CS5, CS6, CS7, CS8};
    t.c_cflag |= sizes[l.data_bits - 5] | CREAD | CLOCAL;
    if (l.parity != 'N') t.c_cflag |= PARENB | (l.parity == 'O' ? PARODD : 0);
    if (l.stop_bits == 2) t.c_cflag |= CSTOPB;
    if (l.rtscts) t.c_cflag |= CRTSCTS;
    cfsetispeed(&t, sp);
    cfsetospeed(&t, sp);
    return tcsetattr(fd, TCSANOW, &t) == 0 ? 0 : -errno;
}

// Wait for `events` on the master: 0 ready, -EAGAIN (non-blocking),
// -ETIMEDOUT, -errno.
int wait_for(const Inst* in, short events) {
    if (in->flags & CHM_DEV_NONBLOCK) return -EAGAIN;
    pollfd p{in->ctx->master, events, 0};
    for (;;) {
        const int r = poll(&p, 1, in->ctx->timeout_ms);
        if (r > 0) return 0;
        if (r == 0) return -ETIMEDOUT;
        if (errno != EINTR) return -errno;
    }
}

int serial_open(void* ctx, int flags, void** inst, std::uint64_t* range) {
    if (static_cast<DevCtx*>(ctx)->master < 0) return -ENODEV;
    *range = 0;  // a stream
    return generic_open(ctx, flags, inst);
}

int64_t serial_read(void* inst, void* buf, std::size_t n, std::uint64_t) {
    const Inst* in = static_cast<Inst*>(inst);
    for (;;) {
        const ssize_t r = read(in->ctx->master, buf, n);
        if (r >= 0) {
            Locked l(in->ctx->sim);
            as<SerialFile>(in->ctx->sim)->rx_bytes += std::uint64_t(r);
            return r;
        }
        if (errno == EINTR) continue;
        if (errno != EAGAIN) return -errno;
        if (const int w = wait_for(in, POLLIN); w < 0) return w;
    }
}

int64_t serial_write(void* inst, const void* buf, std::size_t n, std::uint64_t) {
    const Inst* in = static_cast<Inst*>(inst);
    for (;;) {
        const ssize_t r = write(in->ctx->master, buf, n);
        if (r >= 0) {
            Locked l(in->ctx->sim);
            as<SerialFile>(in->ctx->sim)->tx_bytes += std::uint64_t(r);
            return r;
        }
        if (errno == EINTR) continue;
        if (errno != EAGAIN) return -errno;
        if (const int w = wait_for(in, POLLOUT); w < 0) return w;
    }
}

int serial_ioctl(void* inst, unsigned long req, void* arg) {
    Inst* in = static_cast<Inst*>(inst);
    DevCtx* c = in->ctx;
    if (!arg) return CHM_EDEV_INVAL;
    switch (req) {
    case CHM_DEV_IOC_EVENT_FD: *static_cast<int*>(arg) = c->master; return 0;  // readable: the peer wrote
    case CHM_DEV_IOC_TIME: *static_cast<std::uint64_t*>(arg) = mono_ns(); return 0;
    case CHM_SERIAL_IOC_PEER_NAME: {
        Locked l(c->sim);
        std::memcpy(arg, as<SerialFile>(c->sim)->peer, CHM_SIM_PATH_MAX);
        return 0;
    }
    case CHM_SERIAL_IOC_SET_LINE: {
        if (!(in->flags & CHM_DEV_WRITE)) return CHM_EDEV_ACCES;
        const auto* l = static_cast<const chm_serial_line_t*>(arg);
        const int r = set_line(c->slave, *l);
        if (r == 0) {
            Locked lk(c->sim);
            as<SerialFile>(c->sim)->line = *l;
            bump(c->sim);
        }
        return r;
    }
    case CHM_SERIAL_IOC_GET_LINE: {
        Locked l(c->sim);
        *static_cast<chm_serial_line_t*>(arg) = as<SerialFile>(c->sim)->line;
        return 0;
    }
    case CHM_SERIAL_IOC_SET_TIMEOUT: {
        const std::int32_t ms = *static_cast<const std::int32_t*>(arg);
        if (ms < -1) return CHM_EDEV_INVAL;
        c->timeout_ms = ms;
        return 0;
    }
    default: return CHM_EDEV_NOTTY;
    }
}

}  // namespace

const chm_dev_ops_t kSerialOps = {serial_open, generic_close, serial_read, serial_write, serial_ioctl,
                                  nullptr, nullptr};

int serial_attach(DevCtx* c) {
    const int m = posix_openpt(O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
    if (m < 0) return -errno;
    char name[128];
    int r = grantpt(m) == 0 && unlockpt(m) == 0 && ptsname_r(m, name, sizeof name) == 0 ? 0 : -errno;
    const int s = r == 0 ? open(name, O_RDWR | O_NOCTTY | O_CLOEXEC) : -1;
    if (r == 0 && s < 0) r = -errno;
    const chm_serial_line_t line{115200, 8, 'N', 1, 0};
    if (r == 0) r = set_line(s, line);
    if (r < 0) {
        if (s >= 0) close(s);
        close(m);
        return r;
    }
    c->master = m;
    c->slave = s;
    {
        Locked l(c->sim);
        SerialFile* f = as<SerialFile>(c->sim);
        std::snprintf(f->peer, sizeof f->peer, "%s", name);
        f->owner_pid = std::int32_t(getpid());
        f->line = line;
        bump(c->sim);
    }
    char link[CHM_SIM_PATH_MAX + 8];
    std::snprintf(link, sizeof link, "%s.pty", c->sim->path);
    unlink(link);
    (void)!symlink(name, link);
    return 0;
}

void serial_detach(DevCtx* c) {
    if (c->master < 0) return;
    {
        Locked l(c->sim);
        SerialFile* f = as<SerialFile>(c->sim);
        f->peer[0] = 0;
        f->owner_pid = 0;
        bump(c->sim);
    }
    char link[CHM_SIM_PATH_MAX + 8];
    std::snprintf(link, sizeof link, "%s.pty", c->sim->path);
    unlink(link);
    close(c->slave);
    close(c->master);
    c->master = c->slave = -1;
}

}  // namespace chm::sim

using namespace chm::sim;

extern "C" {

int chm_sim_serial_create(const char* path) {
    if (!path) return -EINVAL;
    SerialFile f{};
    f.line = chm_serial_line_t{115200, 8, 'N', 1, 0};
    return file_create(path, CHM_SIM_SERIAL, &f, sizeof f, kPage);
}

int chm_sim_serial_peer(chm_sim_t* s, char* out, size_t cap) {
    if (!s || chm_sim_kind_of(s) != CHM_SIM_SERIAL || !out || !cap) return -EINVAL;
    Locked l(s);
    const int n = std::snprintf(out, cap, "%s", as<SerialFile>(s)->peer);
    return std::size_t(n) >= cap ? -ENAMETOOLONG : 0;
}

}  // extern "C"
