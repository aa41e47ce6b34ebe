// Simulated robot arm: the rigid-body dynamics of a planar serial chain
// (Eigen), independent of files and drivers so it can be checked alone.
//
// Joint torques come from the recursive Newton-Euler algorithm (RNEA); the
// mass matrix is RNEA with unit accelerations and no velocity or gravity, so
// both stay exact for 1..6 joints without hand-derived formulas. Fixed-size
// storage (at most 6 joints): nothing here allocates.
#pragma once

#include <Eigen/Dense>

#include "sim.h"

namespace chm::sim {

using Vec = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, CHM_SIM_ARM_MAX, 1>;
using Mat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, CHM_SIM_ARM_MAX, CHM_SIM_ARM_MAX>;
using V2 = Eigen::Vector2d;  // (x, z)

class ArmModel {
public:
    explicit ArmModel(const chm_sim_arm_config_t& cfg) : c_(cfg), n_(int(cfg.joints)) {}
    int joints() const { return n_; }

    // Joint torques that produce accelerations qdd at (q, qd) under gravity
    // `g`, with the force `f_tip` applied to the tip by the environment.
    Vec rnea(const Vec& q, const Vec& qd, const Vec& qdd, double g, const V2& f_tip) const;
    Mat mass(const Vec& q) const;

    struct Kin {
        V2 tip, tip_vel;
        double kinetic = 0, potential = 0;
    };
    Kin kinematics(const Vec& q, const Vec& qd) const;

    // The surface's force on the tip (zero when contact is off or the tip is
    // above the surface; the surface pushes, never pulls).
    V2 contact_force(const V2& tip, const V2& tip_vel) const;

    // Forward dynamics: M(q) qdd = tau - B qd - h(q, qd) + J^T f_contact.
    Vec accel(const Vec& q, const Vec& qd, const Vec& tau) const;

    // One classical Runge-Kutta step of length h with tau held constant.
    void step_rk4(Vec& q, Vec& qd, const Vec& tau, double h) const;

private:
    chm_sim_arm_config_t c_;  // a copy: the file may be remapped
    int n_;
};

// The arm's configuration with a held object: its point mass lumped into
// the last link at the tip (mass, centre of mass and inertia about it).
chm_sim_arm_config_t with_payload(const chm_sim_arm_config_t& c, bool held);

// Gripper and object state at creation: jaws open, object on the surface.
void gripper_init(const chm_sim_arm_config_t& c, chm_sim_arm_state_t& s);

// One step of length h of the jaws and the object, the tip being at `tip`
// moving at `tip_vel` after the arm's step. Nothing without a gripper.
void gripper_step(const chm_sim_arm_config_t& c, chm_sim_arm_state_t& s, const V2& tip, const V2& tip_vel,
                  double h);

}  // namespace chm::sim
