// The simulated arm's gripper and object: a grasp within reach, carrying
// (the object follows the tip and the arm feels its weight), a release that
// drops it onto the surface, a grasp that misses, a squeeze too weak to
// lift it, the registers and level-2 vectors, and bad configurations.
//
// The arm is braked (hold-mode safe stop) and placed with set_state, so the
// tip is exactly where each case needs it while the jaws and the object
// follow their own dynamics step by step.
#include <cmath>

#include "chimera/chimera.h"
#include "dev_fixture.hpp"

namespace {

using chm::test::SimDirTest;

constexpr double kSurface = -0.3, kObjX = 0.6;

// Joint angles that put a 2-link arm (0.5 m links) at (x, z), elbow up.
void ik(double x, double z, double q[2]) {
    const double c2 = (x * x + z * z - 0.5) / 0.5;
    q[1] = -std::acos(c2);
    q[0] = std::atan2(z, x) - std::atan2(0.5 * std::sin(q[1]), 0.5 + 0.5 * std::cos(q[1]));
}

class Gripper : public SimDirTest {
protected:
    void SetUp() override {
        SimDirTest::SetUp();
        chm_sim_arm_config_init(&c_, 2);
        c_.clock = CHM_SIM_CLOCK_MANUAL;
        c_.stop_mode = CHM_SIM_STOP_HOLD;
        c_.contact = 1;
        c_.surface_z = kSurface;
        c_.gripper = 1;
        c_.object = 1;
        c_.object_x = kObjX;
    }
    void TearDown() override {
        if (s_) chm_sim_detach(s_);
        SimDirTest::TearDown();
    }
    void make() {
        ASSERT_EQ(chm_sim_arm_create(path("arm").c_str(), &c_), 0);
        ASSERT_EQ(chm_sim_attach(path("arm").c_str(), &s_), 0);
        ASSERT_EQ(chm_sim_arm_stop(s_), 0);  // brakes on: set_state places the arm
    }
    void place(double x, double z) {
        double q[2];
        ik(x, z, q);
        ASSERT_EQ(chm_sim_arm_set_state(s_, q, nullptr, 2), 0);
        const chm_sim_arm_state_t st = state();
        ASSERT_NEAR(st.tip[0], x, 1e-9);
        ASSERT_NEAR(st.tip[1], z, 1e-9);
    }
    chm_sim_arm_state_t state() {
        chm_sim_arm_state_t st{};
        EXPECT_EQ(chm_sim_arm_read(s_, &st), 0);
        return st;
    }
    void seconds(double t) { ASSERT_EQ(chm_sim_arm_step(s_, uint64_t(std::llround(t / c_.dt_s))), 0); }
    chm_sim_arm_config_t c_;
    chm_sim_t* s_ = nullptr;
};

TEST_F(Gripper, StartsOpenWithTheObjectOnTheSurface) {
    make();
    const chm_sim_arm_state_t st = state();
    EXPECT_EQ(st.grip_opening, 0.08);
    EXPECT_EQ(st.grip_cmd, 0.08);
    EXPECT_EQ(st.held, 0u);
    EXPECT_EQ(st.object[0], kObjX);
    EXPECT_EQ(st.object[1], kSurface);
}

TEST_F(Gripper, GraspsCarriesAndReleasesTheObject) {
    make();
    place(kObjX + 0.005, kSurface + 0.01);  // within reach (2 cm)
    ASSERT_EQ(chm_sim_arm_set_grip(s_, 0.0), 0);
    seconds(0.2);  // 0.04 m of travel at 0.1 m/s: not there yet
    EXPECT_EQ(state().held, 0u);
    EXPECT_NEAR(state().grip_opening, 0.06, 1e-9);
    seconds(0.3);
    chm_sim_arm_state_t st = state();
    ASSERT_EQ(st.held, 1u) << "the jaws closed on the object";
    EXPECT_EQ(st.grip_opening, 0.04) << "stopped at its width";
    EXPECT_EQ(st.grip_force, 40.0) << "min(force_max 40, 2000 * 0.04)";
    EXPECT_NEAR(st.object[0], kObjX + 0.005, 1e-12) << "it is in the jaws, at the tip";

    place(0.3, -0.1);
    st = state();
    EXPECT_EQ(st.object[0], st.tip[0]);
    EXPECT_EQ(st.object[1], st.tip[1]);
    seconds(0.1);
    st = state();
    EXPECT_NEAR(st.object[0], 0.3, 1e-9) << "carried";
    EXPECT_NEAR(st.object[1], -0.1, 1e-9);
    EXPECT_EQ(st.held, 1u);
    const double pe_carry = st.potential;  // the object's m g z included: the arm feels it

    ASSERT_EQ(chm_sim_arm_set_grip(s_, 0.08), 0);  // open: it falls 0.2 m (0.2 s)
    seconds(0.05);
    st = state();
    EXPECT_EQ(st.held, 0u);
    EXPECT_LT(st.object[1], -0.1) << "falling";
    EXPECT_GT(st.object[1], kSurface);
    EXPECT_NEAR(pe_carry - st.potential, 0.2 * 9.81 * -0.1, 1e-9) << "the arm no longer carries its weight";
    seconds(0.5);
    st = state();
    EXPECT_NEAR(st.object[0], 0.3, 1e-12) << "straight down";
    EXPECT_EQ(st.object[1], kSurface) << "resting on the surface";
    EXPECT_NEAR(st.grip_opening, 0.08, 1e-12);
}

TEST_F(Gripper, ClosingOutOfReachMissesTheObject) {
    make();
    place(kObjX, kSurface + 0.1);  // 10 cm above it
    ASSERT_EQ(chm_sim_arm_set_grip(s_, 0.0), 0);
    seconds(1.0);
    const chm_sim_arm_state_t st = state();
    EXPECT_EQ(st.held, 0u);
    EXPECT_EQ(st.grip_opening, 0.0) << "closed on nothing";
    EXPECT_EQ(st.grip_force, 0.0);
    EXPECT_EQ(st.object[0], kObjX);
    EXPECT_EQ(st.object[1], kSurface);
}

TEST_F(Gripper, ASqueezeTooWeakForItsWeightDoesNotLiftIt) {
    make();
    place(kObjX, kSurface);
    // 2000 N/m * 0.5 mm = 1 N < 0.2 kg * 9.81 (friction 0.5 on two jaws).
    ASSERT_EQ(chm_sim_arm_set_grip(s_, 0.0395), 0);
    seconds(0.5);
    chm_sim_arm_state_t st = state();
    EXPECT_EQ(st.held, 0u);
    EXPECT_EQ(st.grip_opening, 0.04) << "the jaws touch it";
    EXPECT_NEAR(st.grip_force, 1.0, 1e-9);
    ASSERT_EQ(chm_sim_arm_set_grip(s_, 0.035), 0);  // 10 N: now it holds
    seconds(0.1);
    ASSERT_EQ(state().held, 1u);
    place(kObjX, kSurface + 0.05);
    seconds(0.01);
    ASSERT_NEAR(state().object[1], kSurface + 0.05, 1e-9) << "lifted";
    ASSERT_EQ(chm_sim_arm_set_grip(s_, 0.0395), 0);  // loosened: it slips out
    seconds(0.01);
    st = state();
    EXPECT_EQ(st.held, 0u);
    EXPECT_LT(st.object[1], kSurface + 0.05) << "falling";
    EXPECT_GT(st.object[1], kSurface);
    seconds(0.2);
    EXPECT_EQ(state().object[1], kSurface);
}

// The gripper through the driver: the registers after the arm's, the
// level-2 sensor's (opening, squeeze) and the actuator's grip command.
TEST_F(Gripper, RegistersAndLevelTwoVectorsCarryTheGripper) {
    make();
    ASSERT_EQ(chm_sim_arm_resume(s_), 0);
    reg("arm", "arm");
    const int sd = chm_sensor_open("arm");
    ASSERT_GE(sd, 0);
    chm_sio_info_t info;
    ASSERT_EQ(chm_sensor_info(sd, &info), 0);
    ASSERT_EQ(info.n, 6u);
    EXPECT_STREQ(info.name[4], "grip");
    EXPECT_STREQ(info.name[5], "Fgrip");
    const int ad = chm_actuator_open("arm", nullptr);
    ASSERT_GE(ad, 0);
    ASSERT_EQ(chm_actuator_info(ad, &info), 0);
    ASSERT_EQ(info.n, 3u);
    EXPECT_STREQ(info.name[2], "grip");
    EXPECT_EQ(info.max[2], 0.08);
    const double cmd[3] = {0.0, 0.0, 0.05};
    ASSERT_EQ(chm_actuator_write(ad, cmd, 3), 0);
    EXPECT_EQ(state().grip_cmd, 0.05);
    uint64_t steps = 2000;
    ASSERT_EQ(chm_dev_ioctl(sd, CHM_SIM_IOC_STEP, &steps), 0);
    chm_sensor_sample_t smp;
    ASSERT_EQ(chm_sensor_read(sd, &smp), 0);
    ASSERT_EQ(smp.n, 6u);
    EXPECT_NEAR(smp.v[4], 0.05, 1e-12);
    EXPECT_EQ(smp.v[5], 0.0);

    const int dd = chm_dev_open("arm", CHM_DEV_RDWR);
    ASSERT_GE(dd, 0);
    const uint64_t g = (4 * 2 + 4) * sizeof(double);
    double regs[6];
    ASSERT_EQ(chm_dev_pread(dd, regs, sizeof regs, g), int64_t(sizeof regs));
    EXPECT_EQ(regs[0], 0.05);
    EXPECT_EQ(regs[3], 0.0) << "not held";
    EXPECT_EQ(regs[4], kObjX);
    EXPECT_EQ(regs[5], kSurface);
    const double open = 0.07;
    EXPECT_EQ(chm_dev_pwrite(dd, &open, sizeof open, g), int64_t(sizeof open));
    EXPECT_EQ(state().grip_cmd, 0.07);
    EXPECT_EQ(chm_dev_pwrite(dd, &open, sizeof open, g + sizeof(double)), CHM_EDEV_ACCES) << "opening is read-only";
    const double nan = NAN;
    EXPECT_EQ(chm_dev_pwrite(dd, &nan, sizeof nan, g), CHM_EDEV_INVAL);
    EXPECT_EQ(chm_dev_pread(dd, regs, 8, g + 6 * sizeof(double)), CHM_EDEV_RANGE) << "nothing past the object";
    EXPECT_EQ(chm_dev_close(dd), 0);
    EXPECT_EQ(chm_dev_close(ad), 0);
    EXPECT_EQ(chm_dev_close(sd), 0);
    // The close safe-stopped the arm; it must not have dropped the command.
    EXPECT_EQ(state().grip_cmd, 0.07);
}

TEST_F(Gripper, BadConfigurationsAreRefused) {
    chm_sim_arm_config_t c = c_;
    c.gripper = 0;
    EXPECT_EQ(chm_sim_arm_create(path("a").c_str(), &c), -EINVAL) << "an object needs the gripper";
    c = c_;
    c.contact = 0;
    EXPECT_EQ(chm_sim_arm_create(path("a").c_str(), &c), -EINVAL) << "an object needs the surface";
    c = c_;
    c.object_width = 0.08;
    EXPECT_EQ(chm_sim_arm_create(path("a").c_str(), &c), -EINVAL) << "wider than the jaws open";
    c = c_;
    c.grip_speed = 0;
    EXPECT_EQ(chm_sim_arm_create(path("a").c_str(), &c), -EINVAL);
    c = c_;
    c.object_mass = -1;
    EXPECT_EQ(chm_sim_arm_create(path("a").c_str(), &c), -EINVAL);
    c = c_;
    c.object = 0;
    c.gripper = 0;
    ASSERT_EQ(chm_sim_arm_create(path("plain").c_str(), &c), 0);
    chm_sim_t* s = nullptr;
    ASSERT_EQ(chm_sim_attach(path("plain").c_str(), &s), 0);
    EXPECT_EQ(chm_sim_arm_set_grip(s, 0.01), -EINVAL) << "no gripper";
    chm_sim_detach(s);
}

}  // namespace
