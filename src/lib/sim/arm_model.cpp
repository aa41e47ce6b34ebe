// Simulated robot arm: planar RNEA, mass matrix, contact and RK4.
//
// Conventions: link i's absolute angle th_i = q_1 + ... + q_i from +x
// toward +z; u_i = (cos th_i, sin th_i); perp(r) = (-r.z, r.x) is the
// velocity of a point at r on a body turning at unit rate; the moment of a
// force f at r is cross(r, f) = r.x f.z - r.z f.x (positive turns th up).
#include "arm_model.hpp"

namespace chm::sim {
namespace {

V2 perp(const V2& r) { return V2(-r.y(), r.x()); }
double cross(const V2& r, const V2& f) { return r.x() * f.y() - r.y() * f.x(); }

}  // namespace

Vec ArmModel::rnea(const Vec& q, const Vec& qd, const Vec& qdd, double g, const V2& f_tip) const {
    V2 u[CHM_SIM_ARM_MAX], ac[CHM_SIM_ARM_MAX];
    double al[CHM_SIM_ARM_MAX];
    // Outward: angular rates and the accelerations of joints and centres of
    // mass. The base accelerates up at g: gravity without a separate term.
    double th = 0, wi = 0, ai = 0;
    V2 a_joint(0.0, g);
    for (int i = 0; i < n_; ++i) {
        th += q[i];
        wi += qd[i];
        ai += qdd[i];
        u[i] = V2(std::cos(th), std::sin(th));
        al[i] = ai;
        const V2 rc = c_.com[i] * u[i], rl = c_.length[i] * u[i];
        ac[i] = a_joint + ai * perp(rc) - wi * wi * rc;
        a_joint = a_joint + ai * perp(rl) - wi * wi * rl;
    }
    // Inward: the force and moment each link's joint transmits. The tip
    // passes on -f_tip (what the arm exerts on the environment).
    Vec tau(n_);
    V2 f_next = -f_tip;
    double n_next = 0;
    for (int i = n_ - 1; i >= 0; --i) {
        const V2 fi = c_.mass[i] * ac[i];
        const V2 rc = c_.com[i] * u[i], rl = c_.length[i] * u[i];
        const double ni = n_next + cross(rl, f_next) + cross(rc, fi) + c_.inertia[i] * al[i];
        f_next = f_next + fi;
        n_next = ni;
        tau[i] = ni;
    }
    return tau;
}

Mat ArmModel::mass(const Vec& q) const {
    Mat m(n_, n_);
    const Vec zero = Vec::Zero(n_);
    for (int j = 0; j < n_; ++j) {
        Vec e = Vec::Zero(n_);
        e[j] = 1.0;
        m.col(j) = rnea(q, zero, e, 0.0, V2::Zero());
    }
    return m;
}

ArmModel::Kin ArmModel::kinematics(const Vec& q, const Vec& qd) const {
    Kin k;
    double th = 0, wi = 0;
    V2 p = V2::Zero(), v = V2::Zero();
    for (int i = 0; i < n_; ++i) {
        th += q[i];
        wi += qd[i];
        const V2 u(std::cos(th), std::sin(th));
        const V2 pc = p + c_.com[i] * u, vc = v + wi * perp(c_.com[i] * u);
        k.kinetic += 0.5 * c_.mass[i] * vc.squaredNorm() + 0.5 * c_.inertia[i] * wi * wi;
        k.potential += c_.mass[i] * c_.gravity * pc.y();
        p += c_.length[i] * u;
        v += wi * perp(c_.length[i] * u);
    }
    k.tip = p;
    k.tip_vel = v;
    return k;
}

V2 ArmModel::contact_force(const V2& tip, const V2& tip_vel) const {
    if (!c_.contact) return V2::Zero();
    const double pen = c_.surface_z - tip.y();
    if (pen <= 0) return V2::Zero();
    const double fz = c_.contact_k * pen - c_.contact_c * tip_vel.y();
    return V2(0.0, fz > 0 ? fz : 0.0);
}

Vec ArmModel::accel(const Vec& q, const Vec& qd, const Vec& tau) const {
    V2 f = V2::Zero();
    if (c_.contact) {
        const Kin k = kinematics(q, qd);
        f = contact_force(k.tip, k.tip_vel);
    }
    const Vec h = rnea(q, qd, Vec::Zero(n_), c_.gravity, f);  // bias: Coriolis, gravity, contact
    Vec rhs = tau - h;
    for (int i = 0; i < n_; ++i) rhs[i] -= c_.friction[i] * qd[i];
    return mass(q).llt().solve(rhs);
}

void ArmModel::step_rk4(Vec& q, Vec& qd, const Vec& tau, double h) const {
    const Vec k1q = qd, k1v = accel(q, qd, tau);
    const Vec q2 = q + 0.5 * h * k1q, v2 = qd + 0.5 * h * k1v;
    const Vec k2q = v2, k2v = accel(q2, v2, tau);
    const Vec q3 = q + 0.5 * h * k2q, v3 = qd + 0.5 * h * k2v;
    const Vec k3q = v3, k3v = accel(q3, v3, tau);
    const Vec q4 = q + h * k3q, v4 = qd + h * k3v;
    const Vec k4q = v4, k4v = accel(q4, v4, tau);
    q += h / 6.0 * (k1q + 2 * k2q + 2 * k3q + k4q);
    qd += h / 6.0 * (k1v + 2 * k2v + 2 * k3v + k4v);
}

}  // namespace chm::sim
