// Simulated robot arm: its shared-state file, time keeping and driver.
//
// Time advances in whole integration steps, so the state after a given
// amount of simulated time does not depend on how often, or by which
// process, it was read. Level-1 register space (doubles, J = joints):
//   [0, J) q (rad, RO)   [J, 2J) qd (rad/s, RO)   [2J, 3J) torque command (N*m, RW)
//   [3J, 4J) torque acting (RO)   [4J, 4J+4) tip x, z, vx, vz (RO)
// and with a gripper, G = 4J+4:
//   [G] grip command (m, RW)   [G+1] opening (m)   [G+2] grip force (N)
//   [G+3] held (0/1)   [G+4, G+6) object x, z (m)   (RO)
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>

#include "arm_model.hpp"
#include "chimera/kernel.h"
#include "drivers.hpp"

namespace chm::sim {
namespace {

// Longest stretch integrated in one access; a file left alone longer falls
// behind its clock instead of costing seconds of CPU on the next read.
constexpr std::uint64_t kMaxCatchUpNs = 2000000000;

std::uint64_t dt_ns(const ArmFile* a) { return std::uint64_t(std::llround(a->cfg.dt_s * 1e9)); }

// The model of the arm as it is now: with the object when it holds it.
ArmModel model_of(const ArmFile* a) { return ArmModel(with_payload(a->cfg, a->st.held)); }

void derive_locked(ArmFile* a) {
    const ArmModel m = model_of(a);
    const int n = m.joints();
    Vec q(n), qd(n);
    for (int i = 0; i < n; ++i) { q[i] = a->st.q[i]; qd[i] = a->st.qd[i]; }
    const ArmModel::Kin k = m.kinematics(q, qd);
    const V2 f = m.contact_force(k.tip, k.tip_vel);
    a->st.tip[0] = k.tip.x(); a->st.tip[1] = k.tip.y();
    a->st.tip_vel[0] = k.tip_vel.x(); a->st.tip_vel[1] = k.tip_vel.y();
    a->st.kinetic = k.kinetic;
    a->st.potential = k.potential;
    std::memset(a->st.wrench, 0, sizeof a->st.wrench);
    a->st.wrench[0] = f.x();
    a->st.wrench[2] = f.y();
    a->st.in_contact = a->cfg.contact && k.tip.y() < a->cfg.surface_z;
    for (int i = 0; i < n; ++i) a->st.tau[i] = a->st.stopped ? 0.0 : a->st.tau_cmd[i];
    if (a->st.held) {  // placed by set_state: the object goes with the tip
        a->st.object[0] = k.tip.x();
        a->st.object[1] = k.tip.y();
    }
}

// Integrate `steps` steps. Returns true when contact began during them.
bool steps_locked(chm_sim_t* s, std::uint64_t steps) {
    ArmFile* a = as<ArmFile>(s);
    if (!steps) return false;
    const int n = int(a->cfg.joints);
    Vec q(n), qd(n), tau(n);
    for (int i = 0; i < n; ++i) {
        q[i] = a->st.q[i];
        qd[i] = a->st.qd[i];
        tau[i] = a->st.stopped ? 0.0 : a->st.tau_cmd[i];
    }
    const bool hold = a->st.stopped && a->cfg.stop_mode == CHM_SIM_STOP_HOLD;
    if (hold) qd.setZero();
    bool was = a->st.in_contact, began = false;
    const bool track = a->cfg.contact || a->cfg.gripper;
    ArmModel::Kin kin = model_of(a).kinematics(q, qd);
    for (std::uint64_t k = 0; k < steps; ++k) {
        if (!hold) {
            const ArmModel m = model_of(a);  // the payload changes when the object is taken or let go
            m.step_rk4(q, qd, tau, a->cfg.dt_s);
            if (track) kin = m.kinematics(q, qd);
        }
        if (a->cfg.contact) {
            const bool now = kin.tip.y() < a->cfg.surface_z;
            began |= now && !was;
            was = now;
        }
        gripper_step(a->cfg, a->st, kin.tip, kin.tip_vel, a->cfg.dt_s);
    }
    for (int i = 0; i < n; ++i) { a->st.q[i] = q[i]; a->st.qd[i] = qd[i]; }
    a->st.steps += steps;
    a->st.t_ns = a->st.steps * dt_ns(a);
    derive_locked(a);
    bump(s);
    return began;
}

// Advance to simulated time `target` in whole steps.
bool advance_locked(chm_sim_t* s, std::uint64_t target) {
    ArmFile* a = as<ArmFile>(s);
    if (target <= a->st.t_ns) return false;
    return steps_locked(s, (target - a->st.t_ns) / dt_ns(a));
}

bool sync_monotonic_locked(chm_sim_t* s) {
    ArmFile* a = as<ArmFile>(s);
    const std::uint64_t now = mono_ns();
    std::uint64_t target = now - a->wall_anchor_ns;
    if (target > a->st.t_ns + kMaxCatchUpNs) {  // left alone too long: fall behind
        a->wall_anchor_ns = now - (a->st.t_ns + kMaxCatchUpNs);
        target = a->st.t_ns + kMaxCatchUpNs;
    }
    return advance_locked(s, target);
}

bool is_arm(chm_sim_t* s) { return s && chm_sim_kind_of(s) == CHM_SIM_ARM; }

}  // namespace

bool arm_sync_locked(chm_sim_t* s) {
    ArmFile* a = as<ArmFile>(s);
    switch (a->cfg.clock) {
    case CHM_SIM_CLOCK_MONOTONIC: return sync_monotonic_locked(s);
    case CHM_SIM_CLOCK_KERNEL: {
        // The registering RTPU's clock; the anchor is re-taken when another
        // process (a new RTPU) drives the arm.
        const std::uint64_t now = chm_time_now();
        if (a->kernel_pid != std::int32_t(getpid()) || now < a->kernel_anchor_ns) {
            a->kernel_pid = std::int32_t(getpid());
            a->kernel_anchor_ns = now;
            a->kernel_sim_anchor_ns = a->st.t_ns;
        }
        std::uint64_t target = a->kernel_sim_anchor_ns + (now - a->kernel_anchor_ns);
        if (target > a->st.t_ns + kMaxCatchUpNs) target = a->st.t_ns + kMaxCatchUpNs;
        return advance_locked(s, target);
    }
    default: return false;
    }
}

namespace {

int set_torque_locked(chm_sim_t* s, const double* tau) {
    ArmFile* a = as<ArmFile>(s);
    if (a->st.stopped) return -ESHUTDOWN;
    for (std::uint32_t i = 0; i < a->cfg.joints; ++i) {
        const double lim = a->cfg.tau_max[i];
        a->st.tau_cmd[i] = tau[i] > lim ? lim : tau[i] < -lim ? -lim : tau[i];  // amplifier saturation
    }
    derive_locked(a);
    bump(s);
    return 0;
}

int set_grip_locked(chm_sim_t* s, double opening) {
    ArmFile* a = as<ArmFile>(s);
    if (!a->cfg.gripper || std::isnan(opening)) return -EINVAL;
    a->st.grip_cmd = opening < 0 ? 0.0 : opening > a->cfg.grip_open_max ? a->cfg.grip_open_max : opening;
    bump(s);
    return 0;
}

void stop_locked(chm_sim_t* s) {
    ArmFile* a = as<ArmFile>(s);
    a->st.stopped = 1;
    std::memset(a->st.tau_cmd, 0, sizeof a->st.tau_cmd);
    if (a->cfg.stop_mode == CHM_SIM_STOP_HOLD) std::memset(a->st.qd, 0, sizeof a->st.qd);
    derive_locked(a);
    bump(s);
}

void resume_locked(chm_sim_t* s) {
    ArmFile* a = as<ArmFile>(s);
    a->st.stopped = 0;
    std::memset(a->st.tau_cmd, 0, sizeof a->st.tau_cmd);
    derive_locked(a);
    bump(s);
}

// ---- driver

constexpr std::uint32_t kGripRegs = 6;
std::uint64_t grip_reg(const ArmFile* a) { return (4 * a->cfg.joints + 4) * sizeof(double); }
std::uint64_t arm_range(const ArmFile* a) {
    return (4 * a->cfg.joints + 4 + (a->cfg.gripper ? kGripRegs : 0)) * sizeof(double);
}

int arm_open(void* ctx, int flags, void** inst, std::uint64_t* range) {
    DevCtx* c = static_cast<DevCtx*>(ctx);
    const int r = generic_open(ctx, flags, inst);
    if (r < 0) return r;
    Locked l(c->sim);
    ArmFile* a = as<ArmFile>(c->sim);
    *range = arm_range(a);
    if (flags & CHM_DEV_WRITE) {  // a new owner of the amplifiers: enabled, torque 0
        arm_sync_locked(c->sim);
        resume_locked(c->sim);
    }
    return 0;
}

int arm_close(void* inst) {
    Inst* in = static_cast<Inst*>(inst);
    if (in->flags & CHM_DEV_WRITE) {  // nobody commands the amplifiers any more: safe stop
        {
            Locked l(in->ctx->sim);
            arm_sync_locked(in->ctx->sim);
            stop_locked(in->ctx->sim);
        }
        raise_line(in->ctx->sim);
    }
    return generic_close(inst);
}

int64_t arm_read(void* inst, void* buf, std::size_t n, std::uint64_t off) {
    chm_sim_t* s = static_cast<Inst*>(inst)->ctx->sim;
    double regs[4 * CHM_SIM_ARM_MAX + 4 + kGripRegs];
    bool raise;
    std::uint64_t range;
    {
        Locked l(s);
        raise = arm_sync_locked(s);
        ArmFile* a = as<ArmFile>(s);
        const std::uint32_t j = a->cfg.joints;
        for (std::uint32_t i = 0; i < j; ++i) {
            regs[i] = a->st.q[i];
            regs[j + i] = a->st.qd[i];
            regs[2 * j + i] = a->st.tau_cmd[i];
            regs[3 * j + i] = a->st.tau[i];
        }
        regs[4 * j] = a->st.tip[0];
        regs[4 * j + 1] = a->st.tip[1];
        regs[4 * j + 2] = a->st.tip_vel[0];
        regs[4 * j + 3] = a->st.tip_vel[1];
        const double grip[kGripRegs] = {a->st.grip_cmd, a->st.grip_opening, a->st.grip_force,
                                        double(a->st.held), a->st.object[0], a->st.object[1]};
        std::memcpy(regs + 4 * j + 4, grip, sizeof grip);
        range = arm_range(a);
    }
    if (raise) raise_line(s);
    if (off + n > range) n = std::size_t(range - off);
    std::memcpy(buf, reinterpret_cast<char*>(regs) + off, n);
    return int64_t(n);
}

int64_t arm_write(void* inst, const void* buf, std::size_t n, std::uint64_t off) {
    chm_sim_t* s = static_cast<Inst*>(inst)->ctx->sim;
    Locked l(s);
    ArmFile* a = as<ArmFile>(s);
    const std::uint64_t lo = 2 * a->cfg.joints * sizeof(double), hi = 3 * a->cfg.joints * sizeof(double);
    if (a->cfg.gripper && off == grip_reg(a)) {  // the grip command alone
        if (n != sizeof(double)) return CHM_EDEV_INVAL;
        double v;
        std::memcpy(&v, buf, sizeof v);
        arm_sync_locked(s);
        const int r = set_grip_locked(s, v);
        return r < 0 ? CHM_EDEV_INVAL : int64_t(n);
    }
    if (off < lo || off + n > hi) return CHM_EDEV_ACCES;  // only the torque and grip registers are writable
    if (off % sizeof(double) || n % sizeof(double)) return CHM_EDEV_INVAL;
    double tau[CHM_SIM_ARM_MAX];
    std::memcpy(tau, a->st.tau_cmd, sizeof tau);
    std::memcpy(reinterpret_cast<char*>(tau) + (off - lo), buf, n);
    arm_sync_locked(s);  // the old torque acted until now
    const int r = set_torque_locked(s, tau);
    return r < 0 ? r : int64_t(n);
}

int arm_ioctl(void* inst, unsigned long req, void* arg) {
    Inst* in = static_cast<Inst*>(inst);
    chm_sim_t* s = in->ctx->sim;
    if (req == CHM_DEV_IOC_EVENT_FD) {
        if (!arg) return CHM_EDEV_INVAL;
        *static_cast<int*>(arg) = s->irq_fd;
        return s->irq_fd >= 0 ? 0 : -ENODEV;
    }
    const bool needs_arg = req != CHM_SIO_IOC_ACT_STOP && req != CHM_SIO_IOC_ACT_RESUME;
    if (needs_arg && !arg) return CHM_EDEV_INVAL;
    bool raise = false;
    int r = 0;
    {
        Locked l(s);
        ArmFile* a = as<ArmFile>(s);
        const std::uint32_t j = a->cfg.joints;
        switch (req) {
        case CHM_DEV_IOC_TIME:
            raise = arm_sync_locked(s);
            *static_cast<std::uint64_t*>(arg) = a->st.t_ns;
            break;
        case CHM_SIO_IOC_SENSOR_INFO: {
            auto* info = static_cast<chm_sio_info_t*>(arg);
            std::memset(info, 0, sizeof *info);
            info->n = 2 * j;
            if (a->cfg.gripper) {  // then the jaws: opening and squeeze
                info->n += 2;
                sio_set(info, 2 * j, "grip", "m", 0.0, a->cfg.grip_open_max);
                sio_set(info, 2 * j + 1, "Fgrip", "N", 0.0, a->cfg.grip_force_max);
            }
            info->time_domain = CHM_TIME_SIM;
            char nm[16];
            for (std::uint32_t i = 0; i < j; ++i) {
                std::snprintf(nm, sizeof nm, "q%u", i + 1);
                sio_set(info, i, nm, "rad", -INFINITY, INFINITY);
                std::snprintf(nm, sizeof nm, "qd%u", i + 1);
                sio_set(info, j + i, nm, "rad/s", -INFINITY, INFINITY);
            }
            break;
        }
        case CHM_SIO_IOC_SENSOR_READ: {
            raise = arm_sync_locked(s);
            auto* smp = static_cast<chm_sensor_sample_t*>(arg);
            smp->t_ns = a->st.t_ns;
            smp->n = 2 * j;
            for (std::uint32_t i = 0; i < j; ++i) {
                smp->v[i] = a->st.q[i];
                smp->v[j + i] = a->st.qd[i];
            }
            if (a->cfg.gripper) {
                smp->v[smp->n++] = a->st.grip_opening;
                smp->v[smp->n++] = a->st.grip_force;
            }
            break;
        }
        case CHM_SIO_IOC_ACT_INFO: {
            auto* info = static_cast<chm_sio_info_t*>(arg);
            std::memset(info, 0, sizeof *info);
            info->n = j;
            info->time_domain = CHM_TIME_SIM;
            char nm[16];
            for (std::uint32_t i = 0; i < j; ++i) {
                std::snprintf(nm, sizeof nm, "tau%u", i + 1);
                sio_set(info, i, nm, "N*m", -a->cfg.tau_max[i], a->cfg.tau_max[i]);
            }
            if (a->cfg.gripper) {  // the grip command after the torques
                info->n = j + 1;
                sio_set(info, j, "grip", "m", 0.0, a->cfg.grip_open_max);
            }
            break;
        }
        case CHM_SIO_IOC_ACT_WRITE:
            if (!(in->flags & CHM_DEV_WRITE)) { r = CHM_EDEV_ACCES; break; }
            raise = arm_sync_locked(s);
            r = set_torque_locked(s, static_cast<const double*>(arg));
            if (r == 0 && a->cfg.gripper) r = set_grip_locked(s, static_cast<const double*>(arg)[j]);
            break;
        case CHM_SIO_IOC_ACT_STOP:
            arm_sync_locked(s);
            stop_locked(s);
            raise = true;
            break;
        case CHM_SIO_IOC_ACT_RESUME:
            if (!(in->flags & CHM_DEV_WRITE)) { r = CHM_EDEV_ACCES; break; }
            arm_sync_locked(s);
            resume_locked(s);
            break;
        case CHM_SIM_IOC_STEP:
            steps_locked(s, *static_cast<const std::uint64_t*>(arg));
            raise = true;
            break;
        case CHM_SIM_IOC_ARM_STATE:
            raise = arm_sync_locked(s);
            *static_cast<chm_sim_arm_state_t*>(arg) = a->st;
            break;
        default: r = CHM_EDEV_NOTTY;
        }
    }
    if (raise) raise_line(s);
    return r;
}

}  // namespace

const chm_dev_ops_t kArmOps = {arm_open, arm_close, arm_read, arm_write, arm_ioctl, nullptr, nullptr};

}  // namespace chm::sim

using namespace chm::sim;

extern "C" {

void chm_sim_arm_config_init(chm_sim_arm_config_t* c, uint32_t joints) {
    std::memset(c, 0, sizeof *c);
    c->joints = joints;
    c->clock = CHM_SIM_CLOCK_MONOTONIC;
    c->stop_mode = CHM_SIM_STOP_ZERO_TORQUE;
    c->dt_s = 0.0005;
    c->gravity = 9.81;
    for (int i = 0; i < CHM_SIM_ARM_MAX; ++i) {
        c->length[i] = 0.5;
        c->mass[i] = 1.0;
        c->com[i] = 0.25;
        c->inertia[i] = 1.0 * 0.5 * 0.5 / 12.0;
        c->friction[i] = 0.1;
        c->tau_max[i] = 50.0;
    }
    c->contact_k = 1e4;
    c->contact_c = 50.0;
    c->grip_open_max = 0.08;
    c->grip_speed = 0.1;
    c->grip_force_max = 40.0;
    c->grip_k = 2000.0;
    c->object_mass = 0.2;
    c->object_width = 0.04;
    c->grasp_reach = 0.02;
}

int chm_sim_arm_create(const char* path, const chm_sim_arm_config_t* c) {
    if (!path || !c || c->joints < 1 || c->joints > CHM_SIM_ARM_MAX || !(c->dt_s >= 1e-6 && c->dt_s <= 0.1) ||
        c->clock > CHM_SIM_CLOCK_KERNEL || c->stop_mode > CHM_SIM_STOP_HOLD || !(c->gravity >= 0))
        return -EINVAL;
    for (std::uint32_t i = 0; i < c->joints; ++i)
        if (!(c->length[i] > 0 && c->mass[i] > 0 && c->inertia[i] >= 0 && c->friction[i] >= 0 &&
              c->tau_max[i] > 0 && c->com[i] >= 0 && c->com[i] <= c->length[i]))
            return -EINVAL;
    if (c->contact && !(c->contact_k > 0 && c->contact_c >= 0)) return -EINVAL;
    if (c->gripper && !(c->grip_open_max > 0 && c->grip_speed > 0 && c->grip_force_max > 0 && c->grip_k > 0))
        return -EINVAL;
    if (c->object && !(c->gripper && c->contact && std::isfinite(c->object_x) && c->object_mass > 0 &&
                       c->object_width > 0 && c->object_width < c->grip_open_max && c->grasp_reach > 0))
        return -EINVAL;
    ArmFile f{};
    f.cfg = *c;
    for (std::uint32_t i = 0; i < c->joints; ++i) {
        f.st.q[i] = c->q0[i];
        f.st.qd[i] = c->qd0[i];
    }
    f.st.joints = c->joints;
    f.wall_anchor_ns = mono_ns();
    gripper_init(f.cfg, f.st);
    derive_locked(&f);
    return file_create(path, CHM_SIM_ARM, &f, sizeof f, 2 * kPage);
}

int chm_sim_arm_read(chm_sim_t* s, chm_sim_arm_state_t* out) {
    if (!is_arm(s) || !out) return -EINVAL;
    bool raise = false;
    {
        Locked l(s);
        if (as<ArmFile>(s)->cfg.clock == CHM_SIM_CLOCK_MONOTONIC) raise = sync_monotonic_locked(s);
        *out = as<ArmFile>(s)->st;
    }
    if (raise) raise_line(s);
    return 0;
}

int chm_sim_arm_step(chm_sim_t* s, uint64_t steps) {
    if (!is_arm(s)) return -EINVAL;
    {
        Locked l(s);
        steps_locked(s, steps);
    }
    raise_line(s);
    return 0;
}

int chm_sim_arm_set_torque(chm_sim_t* s, const double* tau, uint32_t n) {
    if (!is_arm(s) || !tau) return -EINVAL;
    Locked l(s);
    if (n != as<ArmFile>(s)->cfg.joints) return -EINVAL;
    if (as<ArmFile>(s)->cfg.clock == CHM_SIM_CLOCK_MONOTONIC) sync_monotonic_locked(s);
    return set_torque_locked(s, tau);
}

int chm_sim_arm_set_state(chm_sim_t* s, const double* q, const double* qd, uint32_t n) {
    if (!is_arm(s)) return -EINVAL;
    Locked l(s);
    ArmFile* a = as<ArmFile>(s);
    if (n != a->cfg.joints) return -EINVAL;
    for (std::uint32_t i = 0; i < n; ++i) {
        a->st.q[i] = q ? q[i] : 0.0;
        a->st.qd[i] = qd ? qd[i] : 0.0;
    }
    derive_locked(a);
    bump(s);
    return 0;
}

int chm_sim_arm_set_grip(chm_sim_t* s, double opening) {
    if (!is_arm(s)) return -EINVAL;
    Locked l(s);
    if (as<ArmFile>(s)->cfg.clock == CHM_SIM_CLOCK_MONOTONIC) sync_monotonic_locked(s);
    return set_grip_locked(s, opening);
}

int chm_sim_arm_stop(chm_sim_t* s) {
    if (!is_arm(s)) return -EINVAL;
    {
        Locked l(s);
        stop_locked(s);
    }
    raise_line(s);
    return 0;
}

int chm_sim_arm_resume(chm_sim_t* s) {
    if (!is_arm(s)) return -EINVAL;
    Locked l(s);
    resume_locked(s);
    return 0;
}

}  // extern "C"
