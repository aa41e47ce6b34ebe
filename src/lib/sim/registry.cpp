// Simulated devices: registering a device's file as a level-1/level-2
// device of this RTPU, by the kind written in the file.
#include <dirent.h>
#include <pthread.h>
#include <sys/stat.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <new>

#include "chimera/irq.h"
#include "drivers.hpp"

namespace chm::sim {
namespace {

struct Entry {
    char name[CHM_DEV_NAME_MAX + 1];
    DevCtx* ctx;
};
pthread_mutex_t g_mu = PTHREAD_MUTEX_INITIALIZER;
Entry g_entries[CHM_DEV_MAX_DEVICES];

// The registry's lock, under the interrupt mask on the kernel thread (a
// task is never preempted holding it; chm_irq_lock does nothing elsewhere).
struct Guard {
    Guard() {
        chm_irq_lock();
        pthread_mutex_lock(&g_mu);
    }
    ~Guard() {
        pthread_mutex_unlock(&g_mu);
        chm_irq_unlock();
    }
};

void free_ctx(DevCtx* c) {
    if (!c) return;
    serial_detach(c);
    chm_sim_detach(c->arm);
    chm_sim_detach(c->sim);
    delete c;
}

}  // namespace

int generic_open(void* ctx, int flags, void** inst) {
    Inst* in = new (std::nothrow) Inst{static_cast<DevCtx*>(ctx), flags};
    if (!in) return -ENOMEM;
    *inst = in;
    return 0;
}

int generic_close(void* inst) {
    delete static_cast<Inst*>(inst);
    return 0;
}

void sio_set(chm_sio_info_t* info, std::uint32_t i, const char* name, const char* unit, double min,
             double max) {
    std::snprintf(info->name[i], sizeof info->name[i], "%s", name);
    std::snprintf(info->unit[i], sizeof info->unit[i], "%s", unit);
    info->min[i] = min;
    info->max[i] = max;
}

}  // namespace chm::sim

using namespace chm::sim;

extern "C" {

int chm_sim_register(const char* devname, const char* path) {
    if (!devname || !path) return -EINVAL;
    DevCtx* c = new (std::nothrow) DevCtx;
    if (!c) return -ENOMEM;
    int r = chm_sim_attach(path, &c->sim);
    const chm_dev_ops_t* ops = nullptr;
    if (r == 0) {
        switch (chm_sim_kind_of(c->sim)) {
        case CHM_SIM_ARM: ops = &kArmOps; break;
        case CHM_SIM_ADC: ops = &kAdcOps; break;
        case CHM_SIM_SERIAL:
            ops = &kSerialOps;
            r = serial_attach(c);
            break;
        case CHM_SIM_FT: {
            ops = &kFtOps;
            const FtFile* f = as<FtFile>(c->sim);
            if (f->cfg.arm_path[0]) {
                r = chm_sim_attach(f->cfg.arm_path, &c->arm);
                if (r == 0 && chm_sim_kind_of(c->arm) != CHM_SIM_ARM) r = -EPROTO;
            }
            break;
        }
        }
    }
    {
        Guard g;
        Entry* slot = nullptr;
        for (Entry& e : g_entries)
            if (!e.ctx) { slot = &e; break; }
        if (r == 0 && !slot) r = -ENOSPC;
        if (r == 0) r = chm_dev_register(devname, ops, c);
        if (r == 0) {
            std::snprintf(slot->name, sizeof slot->name, "%s", devname);
            slot->ctx = c;
        }
    }
    if (r < 0) free_ctx(c);
    return r;
}

int chm_sim_register_dir(const char* dir) {
    if (!dir) dir = chm_sim_dir();
    DIR* d = opendir(dir);
    if (!d) return -errno;
    int n = 0;
    while (const dirent* e = readdir(d)) {
        // Device files only: not the FIFOs, the pty links or half-made files.
        if (e->d_name[0] == '.' || std::strchr(e->d_name, '.')) continue;
        char path[CHM_SIM_PATH_MAX];
        if (std::snprintf(path, sizeof path, "%s/%s", dir, e->d_name) >= int(sizeof path)) continue;
        struct stat sb;
        if (stat(path, &sb) != 0 || !S_ISREG(sb.st_mode)) continue;
        if (chm_sim_register(e->d_name, path) == 0) ++n;
    }
    closedir(d);
    return n;
}

int chm_sim_unregister(const char* devname) {
    if (!devname) return -EINVAL;
    DevCtx* c = nullptr;
    int r;
    {
        Guard g;
        Entry* slot = nullptr;
        for (Entry& e : g_entries)
            if (e.ctx && std::strcmp(e.name, devname) == 0) slot = &e;
        r = slot ? chm_dev_unregister(devname) : -ENOENT;
        if (r == 0) {
            c = slot->ctx;
            *slot = Entry{};
        }
    }
    free_ctx(c);
    return r;
}

}  // extern "C"
