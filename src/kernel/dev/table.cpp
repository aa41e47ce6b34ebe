// Device drivers, level 1: the driver table and the RTPU's descriptors.
//
// One mutex guards both tables, taken only for a few loads and stores; on
// the kernel thread it is taken under the interrupt mask, so a task is never
// preempted holding it (another task of the same RTPU would wait forever).
// Driver operations run outside the mutex, pinned by a reference count, so a
// slow or blocking driver holds up only its own callers.
#include <pthread.h>
#include <unistd.h>

#include <cstdio>
#include <cstring>

#include "kernel/dev/dev.hpp"
#include "port.hpp"

namespace chm::dev {
namespace {

pthread_mutex_t g_mu = PTHREAD_MUTEX_INITIALIZER;
Driver g_drivers[CHM_DEV_MAX_DEVICES];
Slot g_slots[CHM_DEV_MAX_OPEN];

constexpr int kIdxBits = 8;
static_assert(CHM_DEV_MAX_OPEN == 1 << kIdxBits, "descriptor index field");
constexpr std::uint32_t kGenMax = (1u << (31 - kIdxBits)) - 1;

struct Crit {
    bool masked;
    Crit() : masked(port::on_kernel_thread()) {
        if (masked) port::irq_disable();
        pthread_mutex_lock(&g_mu);
    }
    ~Crit() {
        pthread_mutex_unlock(&g_mu);
        if (masked) port::irq_restore();
    }
    Crit(const Crit&) = delete;
    Crit& operator=(const Crit&) = delete;
};

// Holds the interrupt mask (kernel thread only) around a driver call.
struct Mask {
    bool on;
    Mask() : on(port::on_kernel_thread()) { if (on) port::irq_disable(); }
    ~Mask() { if (on) port::irq_restore(); }
};

int encode(int idx, std::uint32_t gen) { return int(gen << kIdxBits) | idx; }

// The slot of an open descriptor, or nullptr. Table lock held.
Slot* lookup_locked(int dd) {
    if (dd < (1 << kIdxBits)) return nullptr;
    Slot& s = g_slots[dd & ((1 << kIdxBits) - 1)];
    if (s.state != SlotState::Open || s.gen != std::uint32_t(dd) >> kIdxBits) return nullptr;
    return &s;
}

int find_driver_locked(const char* name) {
    for (int i = 0; i < CHM_DEV_MAX_DEVICES; ++i)
        if (g_drivers[i].used && std::strcmp(g_drivers[i].name, name) == 0) return i;
    return -1;
}

// The last reference is gone: unmap, stop, close, free. No lock held.
void finish_close(Slot* s) {
    const chm_dev_ops_t* ops = g_drivers[s->driver].ops;
    Mask mask;
    for (Mapping& m : s->maps)
        if (m.addr) {
            if (ops->munmap) ops->munmap(s->inst, m.addr, m.len);
            m = Mapping{};
        }
    actuator_stop_for_close(s, ops);
    ops->close(s->inst);
    Actuator* a = s->act;
    s->act = nullptr;
    if (a) actuator_free(a);
    Crit c;
    g_drivers[s->driver].open_count--;
    s->inst = nullptr;
    s->driver = -1;
    s->state = SlotState::Free;
}

const char* dir_name(bool write) { return write ? "writing" : "reading"; }

int64_t xfer(int dd, void* buf, std::size_t n, std::uint64_t off, bool use_pos, bool write,
             const char* call) {
    Use u(dd, call);
    if (!u.ok()) return u.status;
    Slot* s = u.slot;
    if (!buf && n) return fail(CHM_EDEV_INVAL, call, "%s: NULL buffer", u.name);
    if (!(s->flags & (write ? CHM_DEV_WRITE : CHM_DEV_READ)))
        return fail(CHM_EDEV_ACCES, call, "%s: descriptor %d not opened for %s", u.name, dd,
                    dir_name(write));
    if (!(write ? (void*)u.ops->write : (void*)u.ops->read))
        return fail(CHM_EDEV_NOTSUP, call, "%s: device cannot be %s", u.name,
                    write ? "written" : "read");
    std::uint64_t at = off;
    if (use_pos) {
        Crit c;
        at = s->pos;
    }
    if (s->range) {
        if (at >= s->range)
            return fail(CHM_EDEV_RANGE, call, "%s: offset %llu is past the end of its range (%llu bytes)",
                        u.name, (unsigned long long)at, (unsigned long long)s->range);
        if (n > s->range - at) n = std::size_t(s->range - at);
    }
    const int64_t r = write ? u.ops->write(s->inst, buf, n, at) : u.ops->read(s->inst, buf, n, at);
    if (r < 0)
        return fail(int(r), call, "%s: %s at offset %llu: %s", u.name, write ? "write" : "read",
                    (unsigned long long)at, chm_dev_strerror(int(r)));
    if (use_pos && s->range) {
        Crit c;
        s->pos = at + std::uint64_t(r);
    }
    return r;
}

}  // namespace

Use::Use(int d, const char* c) : dd(d), call(c) {
    {
        Crit cr;
        Slot* s = lookup_locked(d);
        if (s) {
            s->refs++;
            slot = s;
            ops = g_drivers[s->driver].ops;
            name = g_drivers[s->driver].name;
        }
    }
    if (!slot) {
        status = fail(CHM_EDEV_BADF, c, "descriptor %d is not open (closed, stale or never issued)", d);
        return;
    }
    masked_ = port::on_kernel_thread();
    if (masked_) port::irq_disable();
}

Use::~Use() {
    if (!slot) return;
    bool last = false;
    {
        Crit c;
        last = --slot->refs == 0 && slot->state == SlotState::Closing;
    }
    if (last) finish_close(slot);
    if (masked_) port::irq_restore();
}

bool attach_actuator(int dd, Actuator* a) {
    Crit c;
    Slot* s = lookup_locked(dd);
    if (!s || s->act) return false;
    s->act = a;
    return true;
}

int list_open(int* out, int max, bool any_owner, chm_tid_t owner, bool actuators_only) {
    Crit c;
    int k = 0;
    for (int i = 0; i < CHM_DEV_MAX_OPEN && k < max; ++i) {
        const Slot& s = g_slots[i];
        if (s.state != SlotState::Open) continue;
        if (!any_owner && s.owner != owner) continue;
        if (actuators_only && !s.act) continue;
        out[k++] = encode(i, s.gen);
    }
    return k;
}

}  // namespace chm::dev

using namespace chm::dev;

extern "C" {

static int impl_register(const char* name, const chm_dev_ops_t* ops, void* ctx) {
    const char* call = "chm_dev_register";
    if (!name || !*name || !ops || !ops->open || !ops->close)
        return fail(CHM_EDEV_INVAL, call, "NULL or empty name, or ops without open/close");
    if (std::strlen(name) > CHM_DEV_NAME_MAX)
        return fail(-ENAMETOOLONG, call, "device name \"%s\" longer than %d", name, CHM_DEV_NAME_MAX);
    Crit c;
    if (find_driver_locked(name) >= 0)
        return fail(CHM_EDEV_EXIST, call, "a device named \"%s\" is already registered", name);
    for (Driver& d : g_drivers)
        if (!d.used) {
            d = Driver{};
            d.used = true;
            std::strcpy(d.name, name);
            d.ops = ops;
            d.ctx = ctx;
            return 0;
        }
    return fail(-ENOSPC, call, "driver table full (%d devices)", CHM_DEV_MAX_DEVICES);
}

static int impl_unregister(const char* name) {
    const char* call = "chm_dev_unregister";
    if (!name) return fail(CHM_EDEV_INVAL, call, "NULL name");
    Crit c;
    const int i = find_driver_locked(name);
    if (i < 0) return fail(CHM_EDEV_NODEV, call, "no device named \"%s\"", name);
    if (g_drivers[i].open_count)
        return fail(CHM_EDEV_BUSY, call, "\"%s\" has %u open descriptor(s)", name,
                    g_drivers[i].open_count);
    g_drivers[i] = Driver{};
    return 0;
}

static int impl_open(const char* name, int flags) {
    const char* call = "chm_dev_open";
    if (!name) return fail(CHM_EDEV_INVAL, call, "NULL device name");
    if (!(flags & CHM_DEV_RDWR) || (flags & ~(CHM_DEV_RDWR | CHM_DEV_NONBLOCK)))
        return fail(CHM_EDEV_INVAL, call, "%s: bad flags 0x%x (need CHM_DEV_READ and/or CHM_DEV_WRITE)",
                    name, flags);
    int idx = -1, drv = -1;
    const chm_dev_ops_t* ops = nullptr;
    void* ctx = nullptr;
    {
        Crit c;
        drv = find_driver_locked(name);
        if (drv < 0) return fail(CHM_EDEV_NODEV, call, "no device named \"%s\"", name);
        for (int i = 0; i < CHM_DEV_MAX_OPEN; ++i)
            if (g_slots[i].state == SlotState::Free) { idx = i; break; }
        if (idx < 0)
            return fail(CHM_EDEV_MFILE, call, "%s: all %d descriptors are open", name, CHM_DEV_MAX_OPEN);
        Slot& s = g_slots[idx];
        s.state = SlotState::Opening;  // reserved: not usable, not reusable
        s.driver = drv;
        g_drivers[drv].open_count++;
        ops = g_drivers[drv].ops;
        ctx = g_drivers[drv].ctx;
    }
    void* inst = nullptr;
    std::uint64_t range = 0;
    int r;
    {
        Mask m;
        r = ops->open(ctx, flags, &inst, &range);
    }
    Crit c;
    Slot& s = g_slots[idx];
    if (r < 0) {
        g_drivers[drv].open_count--;
        s.state = SlotState::Free;
        s.driver = -1;
        return fail(r, call, "%s: driver refused to open: %s", name, chm_dev_strerror(r));
    }
    s.gen = s.gen >= kGenMax ? 1 : s.gen + 1;
    s.refs = 1;
    s.inst = inst;
    s.range = range;
    s.pos = 0;
    s.flags = flags;
    s.owner = chm_task_self();
    s.act = nullptr;
    s.state = SlotState::Open;
    return encode(idx, s.gen);
}

static int impl_close(int dd) {
    Slot* s = nullptr;
    bool last = false;
    {
        Crit c;
        s = lookup_locked(dd);
        if (s) {
            s->state = SlotState::Closing;
            last = --s->refs == 0;
        }
    }
    if (!s)
        return fail(CHM_EDEV_BADF, "chm_dev_close",
                    "descriptor %d is not open (closed, stale or never issued)", dd);
    if (last) finish_close(s);
    return 0;
}

static int64_t impl_read(int dd, void* buf, size_t n) {
    return xfer(dd, buf, n, 0, true, false, "chm_dev_read");
}
static int64_t impl_write(int dd, const void* buf, size_t n) {
    return xfer(dd, const_cast<void*>(buf), n, 0, true, true, "chm_dev_write");
}
static int64_t impl_pread(int dd, void* buf, size_t n, uint64_t off) {
    return xfer(dd, buf, n, off, false, false, "chm_dev_pread");
}
static int64_t impl_pwrite(int dd, const void* buf, size_t n, uint64_t off) {
    return xfer(dd, const_cast<void*>(buf), n, off, false, true, "chm_dev_pwrite");
}

static int64_t impl_lseek(int dd, int64_t off, int whence) {
    const char* call = "chm_dev_lseek";
    Use u(dd, call);
    if (!u.ok()) return u.status;
    Slot* s = u.slot;
    if (!s->range) return fail(CHM_EDEV_NOTSUP, call, "%s is a stream device (no position)", u.name);
    Crit c;
    int64_t base;
    switch (whence) {
    case SEEK_SET: base = 0; break;
    case SEEK_CUR: base = int64_t(s->pos); break;
    case SEEK_END: base = int64_t(s->range); break;
    default: return fail(CHM_EDEV_INVAL, call, "%s: bad whence %d", u.name, whence);
    }
    const int64_t np = base + off;
    if (np < 0 || uint64_t(np) > s->range)
        return fail(CHM_EDEV_RANGE, call, "%s: position %lld outside its range (0..%llu)", u.name,
                    (long long)np, (unsigned long long)s->range);
    s->pos = uint64_t(np);
    return np;
}

static int impl_ioctl(int dd, unsigned long req, void* arg) {
    const char* call = "chm_dev_ioctl";
    Use u(dd, call);
    if (!u.ok()) return u.status;
    const int r = u.ops->ioctl ? u.ops->ioctl(u.slot->inst, req, arg) : CHM_EDEV_NOTTY;
    if (r == CHM_EDEV_NOTTY)
        return fail(r, call, "%s: unknown ioctl request 0x%lx", u.name, req);
    if (r < 0) return fail(r, call, "%s: ioctl 0x%lx: %s", u.name, req, chm_dev_strerror(r));
    return r;
}

static int impl_event_fd(int dd) {
    int fd = -1;
    const int r = impl_ioctl(dd, CHM_DEV_IOC_EVENT_FD, &fd);
    return r < 0 ? r : fd;
}

static int impl_mmap(int dd, uint64_t off, size_t len, int prot, void** addr) {
    const char* call = "chm_dev_mmap";
    Use u(dd, call);
    if (!u.ok()) return u.status;
    Slot* s = u.slot;
    if (!addr || (prot & ~(CHM_DEV_PROT_READ | CHM_DEV_PROT_WRITE)) || !prot)
        return fail(CHM_EDEV_INVAL, call, "%s: NULL addr or bad prot 0x%x", u.name, prot);
    if (!u.ops->mmap) return fail(CHM_EDEV_NOTSUP, call, "%s cannot be mapped", u.name);
    if (len == 0 || off >= s->range || len > s->range - off)
        return fail(CHM_EDEV_RANGE, call, "%s: [%llu, +%zu) is outside its range (%llu bytes)", u.name,
                    (unsigned long long)off, len, (unsigned long long)s->range);
    if ((prot & CHM_DEV_PROT_WRITE) && !(s->flags & CHM_DEV_WRITE))
        return fail(CHM_EDEV_ACCES, call, "%s: write mapping of a descriptor opened read-only", u.name);
    int m = -1;
    {
        Crit c;
        for (int i = 0; i < kMaxMappings; ++i)
            if (!s->maps[i].addr && !s->maps[i].len) { m = i; s->maps[i].len = 1; break; }  // reserve
    }
    if (m < 0) return fail(-ENOSPC, call, "%s: %d mappings already held", u.name, kMaxMappings);
    void* p = nullptr;
    const int r = u.ops->mmap(s->inst, off, len, prot, &p);
    Crit c;
    if (r < 0) {
        s->maps[m] = Mapping{};
        return fail(r, call, "%s: driver: %s", u.name, chm_dev_strerror(r));
    }
    s->maps[m].addr = p;
    s->maps[m].len = len;
    *addr = p;
    return 0;
}

static int impl_munmap(int dd, void* addr, size_t len) {
    const char* call = "chm_dev_munmap";
    Use u(dd, call);
    if (!u.ok()) return u.status;
    bool found = false;
    {
        Crit c;
        for (Mapping& m : u.slot->maps)
            if (m.addr && m.addr == addr && m.len == len) { m = Mapping{}; found = true; break; }
    }
    if (!found) return fail(CHM_EDEV_INVAL, call, "%s: %p (+%zu) is not a mapping of descriptor %d",
                            u.name, addr, len, dd);
    if (u.ops->munmap) u.ops->munmap(u.slot->inst, addr, len);
    return 0;
}

const char* chm_dev_name(int dd) {
    Crit c;
    Slot* s = lookup_locked(dd);
    return s ? g_drivers[s->driver].name : nullptr;
}

int chm_dev_task_abort(chm_tid_t task) {
    int dds[CHM_DEV_MAX_OPEN];
    const int n = list_open(dds, CHM_DEV_MAX_OPEN, false, task, false);
    int closed = 0;
    for (int i = 0; i < n; ++i)
        if (impl_close(dds[i]) == 0) ++closed;  // close safe-stops an actuator
    return closed;
}

int chm_dev_open_count(void) {
    Crit c;
    int k = 0;
    for (const Slot& s : g_slots)
        if (s.state != SlotState::Free) ++k;
    return k;
}


// The public entry points: the work above, then the one exit that turns a
// reported failure into an error signal (report.cpp), with no lock held.
int chm_dev_register(const char* name, const chm_dev_ops_t* ops, void* ctx) { return int(leave(impl_register(name, ops, ctx))); }
int chm_dev_unregister(const char* name) { return int(leave(impl_unregister(name))); }
int chm_dev_open(const char* name, int flags) { return int(leave(impl_open(name, flags))); }
int chm_dev_close(int dd) { return int(leave(impl_close(dd))); }
int64_t chm_dev_read(int dd, void* buf, size_t n) { return leave(impl_read(dd, buf, n)); }
int64_t chm_dev_write(int dd, const void* buf, size_t n) { return leave(impl_write(dd, buf, n)); }
int64_t chm_dev_pread(int dd, void* buf, size_t n, uint64_t off) { return leave(impl_pread(dd, buf, n, off)); }
int64_t chm_dev_pwrite(int dd, const void* buf, size_t n, uint64_t off) { return leave(impl_pwrite(dd, buf, n, off)); }
int64_t chm_dev_lseek(int dd, int64_t off, int whence) { return leave(impl_lseek(dd, off, whence)); }
int chm_dev_ioctl(int dd, unsigned long req, void* arg) { return int(leave(impl_ioctl(dd, req, arg))); }
int chm_dev_event_fd(int dd) { return int(leave(impl_event_fd(dd))); }
int chm_dev_mmap(int dd, uint64_t off, size_t len, int prot, void** addr) { return int(leave(impl_mmap(dd, off, len, prot, addr))); }
int chm_dev_munmap(int dd, void* addr, size_t len) { return int(leave(impl_munmap(dd, addr, len))); }

}  // extern "C"

namespace chm::dev {
int open_quiet(const char* name, int flags) { return impl_open(name, flags); }
int close_quiet(int dd) { return impl_close(dd); }
}  // namespace chm::dev
