// Simulated force/torque sensor: mounted at an arm's tip (it reads the
// contact wrench the arm's simulation computes, in the arm's time) or on a
// probe whose position another process writes (a spring-damper against the
// surface, stamped with CLOCK_MONOTONIC). Level-1 register space: the
// wrench, 6 doubles (Fx Fy Fz N, Tx Ty Tz N*m), read-only.
#include <cerrno>
#include <cmath>
#include <cstring>

#include "drivers.hpp"

namespace chm::sim {
namespace {

bool is_ft(chm_sim_t* s) { return s && chm_sim_kind_of(s) == CHM_SIM_FT; }

// Probe mode: the force of the surface on the probe. State lock held.
void probe_wrench_locked(FtFile* f, double w[6]) {
    std::memset(w, 0, 6 * sizeof(double));
    const double pen = f->cfg.surface_z - f->probe_pos[2];
    if (pen <= 0) return;
    const double fz = f->cfg.contact_k * pen - f->cfg.contact_c * f->probe_vel[2];
    w[2] = fz > 0 ? fz : 0.0;
}

// The wrench and its time, from the arm (brought up to date) or the probe.
// Returns true when the line must be raised (contact began).
bool read_wrench(chm_sim_t* ft, chm_sim_t* arm, double w[6], std::uint64_t* t, bool from_driver) {
    if (arm) {
        bool raise = false;
        Locked l(arm);
        ArmFile* a = as<ArmFile>(arm);
        if (from_driver) raise = arm_sync_locked(arm);
        else if (a->cfg.clock == CHM_SIM_CLOCK_MONOTONIC) raise = arm_sync_locked(arm);
        std::memcpy(w, a->st.wrench, 6 * sizeof(double));
        *t = a->st.t_ns;
        return raise;
    }
    Locked l(ft);
    probe_wrench_locked(as<FtFile>(ft), w);
    *t = mono_ns();
    return false;
}

int ft_open(void* ctx, int flags, void** inst, std::uint64_t* range) {
    if (flags & CHM_DEV_WRITE) return CHM_EDEV_ACCES;  // a sensor only
    *range = 6 * sizeof(double);
    return generic_open(ctx, flags, inst);
}

int64_t ft_read(void* inst, void* buf, std::size_t n, std::uint64_t off) {
    DevCtx* c = static_cast<Inst*>(inst)->ctx;
    double w[6];
    std::uint64_t t;
    if (read_wrench(c->sim, c->arm, w, &t, true)) raise_line(c->arm);
    if (off + n > sizeof w) n = std::size_t(sizeof w - off);
    std::memcpy(buf, reinterpret_cast<char*>(w) + off, n);
    return int64_t(n);
}

int ft_ioctl(void* inst, unsigned long req, void* arg) {
    DevCtx* c = static_cast<Inst*>(inst)->ctx;
    if (!arg) return req == CHM_SIO_IOC_ACT_STOP || req == CHM_SIO_IOC_ACT_RESUME ? CHM_EDEV_NOTTY : CHM_EDEV_INVAL;
    switch (req) {
    case CHM_DEV_IOC_EVENT_FD: {
        // On an arm, contact onset is found by the arm's simulation: its line.
        const int fd = c->arm ? c->arm->irq_fd : c->sim->irq_fd;
        *static_cast<int*>(arg) = fd;
        return fd >= 0 ? 0 : -ENODEV;
    }
    case CHM_DEV_IOC_TIME: {
        double w[6];
        if (read_wrench(c->sim, c->arm, w, static_cast<std::uint64_t*>(arg), true)) raise_line(c->arm);
        return 0;
    }
    case CHM_SIO_IOC_SENSOR_INFO: {
        auto* info = static_cast<chm_sio_info_t*>(arg);
        std::memset(info, 0, sizeof *info);
        info->n = 6;
        info->time_domain = c->arm ? CHM_TIME_SIM : CHM_TIME_MONOTONIC;
        static const char* const names[6] = {"Fx", "Fy", "Fz", "Tx", "Ty", "Tz"};
        for (std::uint32_t i = 0; i < 6; ++i)
            sio_set(info, i, names[i], i < 3 ? "N" : "N*m", -INFINITY, INFINITY);
        return 0;
    }
    case CHM_SIO_IOC_SENSOR_READ: {
        auto* smp = static_cast<chm_sensor_sample_t*>(arg);
        smp->n = 6;
        if (read_wrench(c->sim, c->arm, smp->v, &smp->t_ns, true)) raise_line(c->arm);
        return 0;
    }
    default: return CHM_EDEV_NOTTY;
    }
}

}  // namespace

const chm_dev_ops_t kFtOps = {ft_open, generic_close, ft_read, nullptr, ft_ioctl, nullptr, nullptr};

}  // namespace chm::sim

using namespace chm::sim;

extern "C" {

void chm_sim_ft_config_init(chm_sim_ft_config_t* c) {
    std::memset(c, 0, sizeof *c);
    c->contact_k = 1e4;
    c->contact_c = 50.0;
}

int chm_sim_ft_create(const char* path, const chm_sim_ft_config_t* c) {
    if (!path || !c || !(c->contact_k > 0) || !(c->contact_c >= 0) ||
        !std::memchr(c->arm_path, 0, sizeof c->arm_path))
        return -EINVAL;
    FtFile f{};
    f.cfg = *c;
    f.probe_pos[2] = c->surface_z + 1.0;  // starts well clear of the surface
    return file_create(path, CHM_SIM_FT, &f, sizeof f, kPage);
}

int chm_sim_ft_set_probe(chm_sim_t* s, const double pos[3], const double vel[3]) {
    if (!is_ft(s) || !pos) return -EINVAL;
    bool began;
    {
        Locked l(s);
        FtFile* f = as<FtFile>(s);
        if (f->cfg.arm_path[0]) return -EINVAL;  // mounted on an arm: the arm moves it
        std::memcpy(f->probe_pos, pos, sizeof f->probe_pos);
        if (vel) std::memcpy(f->probe_vel, vel, sizeof f->probe_vel);
        else std::memset(f->probe_vel, 0, sizeof f->probe_vel);
        f->probe_t_ns = mono_ns();
        const std::uint32_t now = f->probe_pos[2] < f->cfg.surface_z;
        began = now && !f->in_contact;
        f->in_contact = now;
        bump(s);
    }
    if (began) raise_line(s);
    return 0;
}

int chm_sim_ft_read(chm_sim_t* s, double wrench[6], uint64_t* t_ns) {
    if (!is_ft(s) || !wrench) return -EINVAL;
    char arm_path[CHM_SIM_PATH_MAX];
    {
        Locked l(s);
        std::memcpy(arm_path, as<FtFile>(s)->cfg.arm_path, sizeof arm_path);
    }
    std::uint64_t t = 0;
    if (arm_path[0]) {
        chm_sim_t* arm = nullptr;
        if (int r = chm_sim_attach(arm_path, &arm); r < 0) return r;
        const bool raise = chm_sim_kind_of(arm) == CHM_SIM_ARM && read_wrench(s, arm, wrench, &t, false);
        const bool ok = chm_sim_kind_of(arm) == CHM_SIM_ARM;
        if (raise) raise_line(arm);
        chm_sim_detach(arm);
        if (!ok) return -EPROTO;
    } else {
        read_wrench(s, nullptr, wrench, &t, false);
    }
    if (t_ns) *t_ns = t;
    return 0;
}

}  // extern "C"
