// The simulated arm behind levels 1 and 2: its physics against analytic
// results and conservation laws, and the actuator's limits and safe stop.
#include <cmath>
#include <cstring>

#include "chimera/chimera.h"
#include "dev_fixture.hpp"

namespace {

using chm::test::SimDirTest;

class Arm : public SimDirTest {
protected:
    // Create an arm file "name", register it as device "name", attach it.
    chm_sim_t* make(const char* name, const chm_sim_arm_config_t& c) {
        EXPECT_EQ(chm_sim_arm_create(path(name).c_str(), &c), 0);
        reg(name, name);
        chm_sim_t* s = nullptr;
        EXPECT_EQ(chm_sim_attach(path(name).c_str(), &s), 0);
        sims_.push_back(s);
        return s;
    }
    void TearDown() override {
        for (chm_sim_t* s : sims_) chm_sim_detach(s);
        SimDirTest::TearDown();
    }
    static chm_sim_arm_state_t state(chm_sim_t* s) {
        chm_sim_arm_state_t st;
        EXPECT_EQ(chm_sim_arm_read(s, &st), 0);
        return st;
    }
    static void step(int dd, uint64_t n) { ASSERT_EQ(chm_dev_ioctl(dd, CHM_SIM_IOC_STEP, &n), 0); }
    std::vector<chm_sim_t*> sims_;
};

chm_sim_arm_config_t manual(uint32_t joints, double gravity) {
    chm_sim_arm_config_t c;
    chm_sim_arm_config_init(&c, joints);
    c.clock = CHM_SIM_CLOCK_MANUAL;
    c.gravity = gravity;
    return c;
}

// One joint, no gravity, viscous friction b, constant torque tau:
// I qdd = tau - b qd  =>  qd = tau/b (1 - e^(-bt/I)),
// q = tau/b t - tau I / b^2 (1 - e^(-bt/I)), I = inertia + m com^2.
TEST_F(Arm, SingleJointUnderConstantTorqueFollowsTheAnalyticSolution) {
    chm_sim_arm_config_t c = manual(1, 0.0);
    c.dt_s = 0.001;
    c.mass[0] = 2.0;
    c.length[0] = 1.0;
    c.com[0] = 0.5;
    c.inertia[0] = 0.1;
    c.friction[0] = 0.5;
    make("arm1", c);
    const int sd = chm_sensor_open("arm1");
    const int ad = chm_actuator_open("arm1", nullptr);
    ASSERT_GE(sd, 0);
    ASSERT_GE(ad, 0);
    chm_sio_info_t info;
    ASSERT_EQ(chm_sensor_info(sd, &info), 0);
    EXPECT_EQ(info.n, 2u);
    EXPECT_STREQ(info.name[0], "q1");
    EXPECT_STREQ(info.unit[0], "rad");
    EXPECT_STREQ(info.unit[1], "rad/s");
    EXPECT_EQ(info.time_domain, uint32_t(CHM_TIME_SIM));
    const double tau = 1.5, b = 0.5, I = 0.1 + 2.0 * 0.25;
    ASSERT_EQ(chm_actuator_write(ad, &tau, 1), 0);
    for (int k = 1; k <= 20; ++k) {
        step(sd, 100);  // 0.1 s
        chm_sensor_sample_t s;
        ASSERT_EQ(chm_sensor_read(sd, &s), 0);
        const double t = 0.1 * k;
        ASSERT_EQ(s.t_ns, uint64_t(k) * 100000000u);
        const double e = std::exp(-b * t / I);
        EXPECT_NEAR(s.v[0], tau / b * t - tau * I / (b * b) * (1 - e), 1e-9) << "t=" << t;
        EXPECT_NEAR(s.v[1], tau / b * (1 - e), 1e-9) << "t=" << t;
    }
    EXPECT_EQ(chm_dev_close(ad), 0);
    EXPECT_EQ(chm_dev_close(sd), 0);
}

// Without friction or torque, a 3-link arm released from a raised pose
// swings under gravity; RK4 keeps kinetic + potential energy constant.
TEST_F(Arm, SwingsUnderGravityAndConservesEnergyWithoutFriction) {
    chm_sim_arm_config_t c = manual(3, 9.81);
    for (int i = 0; i < 3; ++i) c.friction[i] = 0.0;
    c.q0[0] = 0.3;
    c.q0[1] = -0.2;
    c.q0[2] = 0.5;
    chm_sim_t* s = make("arm3", c);
    const int sd = chm_sensor_open("arm3");
    ASSERT_GE(sd, 0);
    const chm_sim_arm_state_t s0 = state(s);
    const double e0 = s0.kinetic + s0.potential;
    EXPECT_EQ(s0.kinetic, 0.0);
    double max_dev = 0, max_speed = 0, min_q0 = s0.q[0];
    for (int k = 0; k < 40; ++k) {  // 2 s in 50 ms slices
        step(sd, 100);
        const chm_sim_arm_state_t st = state(s);
        max_dev = std::max(max_dev, std::fabs(st.kinetic + st.potential - e0));
        max_speed = std::max(max_speed, std::fabs(st.qd[0]));
        min_q0 = std::min(min_q0, st.q[0]);
    }
    EXPECT_LT(min_q0, -1.0) << "the arm did not swing down";
    EXPECT_GT(max_speed, 1.0);
    EXPECT_LT(max_dev, 1e-6 * 3 * 9.81 * 1.5) << "energy drift " << max_dev << " J";
    char drift[32];
    std::snprintf(drift, sizeof drift, "%.3g", max_dev);
    RecordProperty("energy_drift_J", drift);
    EXPECT_EQ(chm_dev_close(sd), 0);
}

// Gravity's sign and size, independently of the simulator's formulas: the
// torques that hold two links horizontal are g m1 c1 + g m2 (l1 + c2) and
// g m2 c2; with them the arm stays put, with none it falls.
TEST_F(Arm, HoldingTorqueBalancesGravity) {
    chm_sim_arm_config_t c = manual(2, 9.81);
    c.mass[1] = 2.0;
    c.com[1] = 0.3;
    chm_sim_t* s = make("arm2", c);
    const int ad = chm_actuator_open("arm2", nullptr);
    ASSERT_GE(ad, 0);
    const double g = 9.81;
    const double hold[2] = {g * (1.0 * 0.25 + 2.0 * (0.5 + 0.3)), g * 2.0 * 0.3};
    ASSERT_EQ(chm_actuator_write(ad, hold, 2), 0);
    step(ad, 2000);
    chm_sim_arm_state_t st = state(s);
    EXPECT_NEAR(st.q[0], 0.0, 1e-9);
    EXPECT_NEAR(st.q[1], 0.0, 1e-9);
    const double none[2] = {0, 0};
    ASSERT_EQ(chm_actuator_write(ad, none, 2), 0);
    step(ad, 200);
    st = state(s);
    EXPECT_LT(st.q[0], -0.05) << "without torque the arm must fall (q decreases toward -z)";
    EXPECT_EQ(chm_dev_close(ad), 0);
}

TEST_F(Arm, LimitsClampAndRefuseAsConfiguredAndAreReported) {
    chm_sim_t* s = make("arm2", manual(2, 0.0));
    chm_actuator_limits_t lim;
    chm_sio_info_t info;
    {
        const int probe = chm_dev_open("arm2", CHM_DEV_READ);
        ASSERT_GE(probe, 0);
        ASSERT_EQ(chm_actuator_info(probe, &info), 0);
        EXPECT_EQ(chm_dev_close(probe), 0);
    }
    EXPECT_STREQ(info.unit[0], "N*m");
    EXPECT_EQ(info.max[0], 50.0);
    chm_actuator_limits_init(&lim, &info);
    lim.min[0] = lim.min[1] = -2.0;
    lim.max[0] = lim.max[1] = 2.0;
    const int ad = chm_actuator_open("arm2", &lim);
    ASSERT_GE(ad, 0);

    const double over[2] = {5.0, -1.0};
    EXPECT_EQ(chm_actuator_write(ad, over, 2), CHM_ACT_CLAMPED);
    EXPECT_NE(std::strstr(chm_dev_last_error(), "element 0 = 5 clamped to 2"), nullptr) << chm_dev_last_error();
    chm_sim_arm_state_t st = state(s);
    EXPECT_EQ(st.tau[0], 2.0);
    EXPECT_EQ(st.tau[1], -1.0);

    lim.mode = CHM_LIMIT_REFUSE;
    ASSERT_EQ(chm_actuator_set_limits(ad, &lim), 0);
    const double far[2] = {0.5, -7.0};
    EXPECT_EQ(chm_actuator_write(ad, far, 2), CHM_EACT_LIMIT);
    st = state(s);
    EXPECT_EQ(st.tau[0], 2.0) << "a refused command reached the amplifier";
    EXPECT_EQ(st.tau[1], -1.0);
    const double nan[2] = {NAN, 0.0};
    EXPECT_EQ(chm_actuator_write(ad, nan, 2), CHM_ESIO_INVAL);
    EXPECT_EQ(chm_actuator_write(ad, over, 1), CHM_ESIO_INVAL);

    // Rate limit: 10 N*m/s in the arm's (simulated) time.
    lim.mode = CHM_LIMIT_CLAMP;
    lim.min[0] = lim.min[1] = -50.0;
    lim.max[0] = lim.max[1] = 50.0;
    lim.max_rate[0] = lim.max_rate[1] = 10.0;
    ASSERT_EQ(chm_actuator_set_limits(ad, &lim), 0);
    step(ad, 200);  // 0.1 s at 0.5 ms
    const double jump[2] = {5.0, -0.5};
    EXPECT_EQ(chm_actuator_write(ad, jump, 2), CHM_ACT_CLAMPED);
    st = state(s);
    EXPECT_DOUBLE_EQ(st.tau[0], 3.0);   // 2 + 10 * 0.1
    EXPECT_DOUBLE_EQ(st.tau[1], -0.5);  // within the rate

    chm_actuator_stats_t stats;
    ASSERT_EQ(chm_actuator_stats(ad, &stats), 0);
    EXPECT_EQ(stats.writes, 2u);
    EXPECT_EQ(stats.clamped, 2u);
    EXPECT_EQ(stats.refused, 1u);
    EXPECT_EQ(stats.rate_limited, 1u);
    EXPECT_DOUBLE_EQ(stats.last[0], 3.0);

    // Limits wider than the hardware, or inverted, are refused.
    lim.max[0] = 60.0;
    EXPECT_EQ(chm_actuator_set_limits(ad, &lim), CHM_ESIO_INVAL);
    lim.max[0] = -60.0;
    EXPECT_EQ(chm_actuator_set_limits(ad, &lim), CHM_ESIO_INVAL);
    EXPECT_EQ(chm_dev_close(ad), 0);
}

TEST_F(Arm, AmplifierSaturatesRawLevelOneWrites) {
    chm_sim_t* s = make("arm2", manual(2, 0.0));
    const int dd = chm_dev_open("arm2", CHM_DEV_RDWR);
    ASSERT_GE(dd, 0);
    const double tau[2] = {80.0, -1.25};
    EXPECT_EQ(chm_dev_pwrite(dd, tau, sizeof tau, 4 * sizeof(double)), int64_t(sizeof tau));
    chm_sim_arm_state_t st = state(s);
    EXPECT_EQ(st.tau_cmd[0], 50.0);
    EXPECT_EQ(st.tau_cmd[1], -1.25);
    double q[2];
    EXPECT_EQ(chm_dev_pwrite(dd, q, sizeof q, 0), CHM_EDEV_ACCES);  // encoders are read-only
    EXPECT_EQ(chm_dev_pwrite(dd, tau, 3, 4 * sizeof(double)), CHM_EDEV_INVAL);
    step(dd, 10);
    double regs[2 * 4 + 4];
    EXPECT_EQ(chm_dev_pread(dd, regs, sizeof regs, 0), int64_t(sizeof regs));
    st = state(s);
    EXPECT_EQ(regs[0], st.q[0]);
    EXPECT_EQ(regs[3], st.qd[1]);
    EXPECT_EQ(regs[6], 50.0);  // acting torque of joint 1
    EXPECT_EQ(regs[8], st.tip[0]);
    EXPECT_EQ(chm_dev_pread(dd, regs, 8, sizeof regs), CHM_EDEV_RANGE);
    EXPECT_EQ(chm_dev_close(dd), 0);
    EXPECT_EQ(state(s).tau[0], 0.0) << "closing the amplifiers' owner must stop them";
}

TEST_F(Arm, SafeStopZeroesTorqueAndLatches) {
    chm_sim_t* s = make("arm2", manual(2, 0.0));
    const int ad = chm_actuator_open("arm2", nullptr);
    ASSERT_GE(ad, 0);
    const int ev = chm_dev_event_fd(ad);
    ASSERT_GE(ev, 0);
    chm::test::drain(ev);
    const double tau[2] = {1.0, 0.0};
    ASSERT_EQ(chm_actuator_write(ad, tau, 2), 0);
    step(ad, 200);
    chm::test::drain(ev);
    EXPECT_GT(state(s).qd[0], 0.0);
    ASSERT_EQ(chm_actuator_stop(ad), 0);
    EXPECT_TRUE(chm::test::readable_within(ev, 1000)) << "a safe stop raises the line";
    chm_sim_arm_state_t st = state(s);
    EXPECT_EQ(st.stopped, 1u);
    EXPECT_EQ(st.tau[0], 0.0);
    EXPECT_EQ(st.tau[1], 0.0);
    EXPECT_EQ(chm_actuator_write(ad, tau, 2), CHM_EACT_STOPPED);
    const double v0 = st.qd[0];
    step(ad, 400);
    EXPECT_LT(std::fabs(state(s).qd[0]), std::fabs(v0)) << "coasting with zero torque slows down under friction";
    ASSERT_EQ(chm_actuator_resume(ad), 0);
    EXPECT_EQ(chm_actuator_write(ad, tau, 2), 0);
    EXPECT_EQ(state(s).tau[0], 1.0);
    chm_actuator_stats_t stats;
    ASSERT_EQ(chm_actuator_stats(ad, &stats), 0);
    EXPECT_EQ(stats.stops, 1u);
    EXPECT_EQ(chm_dev_close(ad), 0);
    st = state(s);
    EXPECT_EQ(st.tau[0], 0.0) << "close stops the actuator";
    EXPECT_EQ(st.stopped, 1u);
}

TEST_F(Arm, HoldModeBrakesTheJoints) {
    chm_sim_arm_config_t c = manual(2, 9.81);
    c.stop_mode = CHM_SIM_STOP_HOLD;
    chm_sim_t* s = make("arm2", c);
    const int ad = chm_actuator_open("arm2", nullptr);
    ASSERT_GE(ad, 0);
    step(ad, 100);  // falling
    EXPECT_LT(state(s).qd[0], 0.0);
    ASSERT_EQ(chm_actuator_stop(ad), 0);
    const chm_sim_arm_state_t a = state(s);
    step(ad, 1000);
    const chm_sim_arm_state_t b = state(s);
    EXPECT_EQ(b.qd[0], 0.0);
    EXPECT_EQ(b.q[0], a.q[0]);
    EXPECT_EQ(b.q[1], a.q[1]);
    EXPECT_GT(b.t_ns, a.t_ns);
    EXPECT_EQ(chm_dev_close(ad), 0);
}

// The monotonic clock: the simulation advances by elapsed time, in whole
// steps, on every access by anyone.
TEST_F(Arm, MonotonicClockAdvancesByElapsedTime) {
    chm_sim_arm_config_t c;
    chm_sim_arm_config_init(&c, 2);
    chm_sim_t* s = make("arm2", c);
    const chm_sim_arm_state_t a = state(s);
    usleep(30000);
    const chm_sim_arm_state_t b = state(s);
    EXPECT_GE(b.t_ns - a.t_ns, 30000000u - 500000u);
    EXPECT_EQ(b.t_ns % 500000u, 0u) << "time advances in whole steps";
    EXPECT_LT(b.q[0], 0.0) << "the arm fell meanwhile";
}

// The hook the error layer calls when it aborts a task: the task's
// actuators stop and its descriptors close.
struct AbortCtx {
    int ad = -1;
    chm_tid_t owner = CHM_TID_NONE;
    int closed = -1;
};

TEST_F(Arm, AbortingTheOwningTaskStopsItsActuator) {
    chm_sim_t* s = make("arm2", manual(2, 0.0));
    chm_kernel_config_t cfg;
    chm_kernel_config_init(&cfg);
    cfg.virtual_clock = 1;
    ASSERT_EQ(chm_kernel_init(&cfg), 0);
    AbortCtx ctx;
    chm_task_attr_t at;
    chm_task_attr_init(&at);
    at.priority = 2;
    ASSERT_EQ(chm_task_spawn(&ctx.owner, [](void* p) {
        auto* c = static_cast<AbortCtx*>(p);
        c->ad = chm_actuator_open("arm2", nullptr);
        const double tau[2] = {3.0, -3.0};
        (void)chm_actuator_write(c->ad, tau, 2);
        (void)chm_task_suspend(chm_task_self());
    }, &ctx, &at), 0);
    at.priority = 1;
    chm_tid_t b;
    ASSERT_EQ(chm_task_spawn(&b, [](void* p) {
        auto* c = static_cast<AbortCtx*>(p);
        c->closed = chm_dev_task_abort(c->owner);
        (void)chm_task_destroy(c->owner);
    }, &ctx, &at), 0);
    (void)chm_kernel_run();
    chm_kernel_fini();
    ASSERT_GE(ctx.ad, 0);
    EXPECT_EQ(ctx.closed, 1);
    const chm_sim_arm_state_t st = state(s);
    EXPECT_EQ(st.stopped, 1u);
    EXPECT_EQ(st.tau[0], 0.0);
    EXPECT_EQ(st.tau[1], 0.0);
    EXPECT_EQ(chm_actuator_write(ctx.ad, st.tau, 2), CHM_EDEV_BADF);
}

// The same through the error layer: a task driving the arm raises an error
// with no handler; the default handler aborts it, and its actuator goes to
// its safe stop before anything else runs.
TEST_F(Arm, ATaskAbortedByAnErrorLeavesItsActuatorStopped) {
    chm_sim_t* s = make("arm3", manual(2, 0.0));
    chm_kernel_config_t cfg;
    chm_kernel_config_init(&cfg);
    cfg.virtual_clock = 1;
    ASSERT_EQ(chm_kernel_init(&cfg), 0);
    static int ad = -1;
    static bool ran_on = false;
    chm_tid_t t;
    ASSERT_EQ(chm_task_spawn(&t, [](void*) {
        ad = chm_actuator_open("arm3", nullptr);
        const double tau[2] = {2.0, -2.0};
        (void)chm_actuator_write(ad, tau, 2);
        chm_err_invoke(CHM_ERR_KERNEL, CHM_EK_HEAP);  // no handler: aborts this task
        ran_on = true;
    }, nullptr, nullptr), 0);
    (void)chm_kernel_run();
    chm_kernel_fini();
    ASSERT_GE(ad, 0);
    EXPECT_FALSE(ran_on) << "the default handler did not abort the task";
    const chm_sim_arm_state_t st = state(s);
    EXPECT_EQ(st.stopped, 1u);
    EXPECT_EQ(st.tau[0], 0.0);
    EXPECT_EQ(st.tau[1], 0.0);
}

// A periodic control task on the kernel's virtual clock drives a 2-joint
// arm (kernel clock) to a set-point with PID through level 2.
struct Loop {
    int sd = -1, ad = -1;
    double target[2] = {0.6, -0.4};
    double integ[2] = {0, 0};
    int cycles = 0;
    double err = 1, speed = 1;
};

TEST_F(Arm, JointPositionLoopConverges) {
    chm_sim_arm_config_t c;
    chm_sim_arm_config_init(&c, 2);
    c.clock = CHM_SIM_CLOCK_KERNEL;
    make("arm2", c);
    chm_kernel_config_t cfg;
    chm_kernel_config_init(&cfg);
    cfg.virtual_clock = 1;
    ASSERT_EQ(chm_kernel_init(&cfg), 0);
    Loop loop;
    chm_task_attr_t at;
    chm_task_attr_init(&at);
    at.name = "servo";
    at.period_ns = 1000000;  // 1 kHz
    chm_tid_t t;
    ASSERT_EQ(chm_task_spawn(&t, [](void* p) {
        auto* L = static_cast<Loop*>(p);
        if (L->sd < 0) {
            L->sd = chm_sensor_open("arm2");
            L->ad = chm_actuator_open("arm2", nullptr);
        }
        for (; L->cycles < 3000; ++L->cycles) {
            chm_sensor_sample_t s;
            if (chm_sensor_read(L->sd, &s) < 0) break;
            double tau[2];
            for (int j = 0; j < 2; ++j) {
                const double e = L->target[j] - s.v[j];
                L->integ[j] += e * 1e-3;
                tau[j] = 300 * e + 1500 * L->integ[j] - 30 * s.v[2 + j];
            }
            L->err = std::max(std::fabs(L->target[0] - s.v[0]), std::fabs(L->target[1] - s.v[1]));
            L->speed = std::max(std::fabs(s.v[2]), std::fabs(s.v[3]));
            (void)chm_actuator_write(L->ad, tau, 2);
            chm_task_wait_period();
        }
        (void)chm_dev_close(L->ad);
        (void)chm_dev_close(L->sd);
    }, &loop, &at), 0);
    (void)chm_kernel_run();
    chm_kernel_fini();
    EXPECT_EQ(loop.cycles, 3000);
    EXPECT_LT(loop.err, 2e-3) << "position error after 3 s";
    EXPECT_LT(loop.speed, 1e-2);
}

}  // namespace
