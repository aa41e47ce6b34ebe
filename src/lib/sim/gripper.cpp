// Simulated gripper and object: a 1-DOF jaw at the arm's tip and a point
// mass it can pick up, carry and put down (sim.h, chm_sim_arm_config_t).
// Plain functions over the configuration and state, so the arm's file
// code steps them with the arm and tests can check them alone.
#include <algorithm>
#include <cmath>

#include "arm_model.hpp"

namespace chm::sim {

chm_sim_arm_config_t with_payload(const chm_sim_arm_config_t& c, bool held) {
    chm_sim_arm_config_t e = c;
    if (!held || !c.object || c.joints < 1) return e;
    // Parallel-axis theorem: the link and the point mass at its end as one body.
    const std::uint32_t i = c.joints - 1;
    const double m = c.mass[i], mo = c.object_mass, l = c.length[i];
    const double com = (m * c.com[i] + mo * l) / (m + mo);
    e.inertia[i] = c.inertia[i] + m * (c.com[i] - com) * (c.com[i] - com) + mo * (l - com) * (l - com);
    e.mass[i] = m + mo;
    e.com[i] = com;
    return e;
}

void gripper_init(const chm_sim_arm_config_t& c, chm_sim_arm_state_t& s) {
    if (!c.gripper) return;
    s.grip_cmd = s.grip_opening = c.grip_open_max;
    if (c.object) {
        s.object[0] = c.object_x;
        s.object[1] = c.surface_z;
    }
}

namespace {

// The squeeze of jaws stopped on the object by a command below its width.
double squeeze(const chm_sim_arm_config_t& c, double cmd) {
    return std::min(c.grip_force_max, c.grip_k * (c.object_width - cmd));
}

bool carries(const chm_sim_arm_config_t& c, double force) { return force >= c.object_mass * c.gravity; }

}  // namespace

void gripper_step(const chm_sim_arm_config_t& c, chm_sim_arm_state_t& s, const V2& tip, const V2& tip_vel,
                  double h) {
    if (!c.gripper) return;
    const double cmd = std::clamp(s.grip_cmd, 0.0, c.grip_open_max);
    const double w = c.object_width;
    if (s.held && (cmd >= w || !carries(c, squeeze(c, cmd)))) {  // opened, or it slips out
        s.held = 0;
        s.object_vel[0] = s.object_vel[1] = 0.0;
    }
    if (s.held) {
        s.grip_opening = w;
        s.grip_force = squeeze(c, cmd);
        s.object[0] = tip.x();
        s.object[1] = tip.y();
        s.object_vel[0] = tip_vel.x();
        s.object_vel[1] = tip_vel.y();
        return;
    }
    // Free jaws move toward the command; closing past the object's width
    // stops on it when it lies between them.
    const double before = s.grip_opening, d = c.grip_speed * h;
    double next = before + std::clamp(cmd - before, -d, d);
    s.grip_force = 0.0;
    if (c.object && before >= w && next < w &&
        std::hypot(tip.x() - s.object[0], tip.y() - s.object[1]) <= c.grasp_reach) {
        next = w;
        s.grip_force = squeeze(c, cmd);
        s.held = carries(c, s.grip_force);
    }
    s.grip_opening = next;
    if (s.held) {
        s.object[0] = tip.x();
        s.object[1] = tip.y();
        return;
    }
    if (!c.object) return;
    // A free object falls onto the surface and rests there.
    if (s.object[1] > c.surface_z) {
        s.object_vel[1] -= c.gravity * h;
        s.object[1] += s.object_vel[1] * h;
    }
    if (s.object[1] <= c.surface_z) {
        s.object[1] = c.surface_z;
        s.object_vel[0] = s.object_vel[1] = 0.0;
    }
}

}  // namespace chm::sim
