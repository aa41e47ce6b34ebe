// The simulated force/torque sensor: zero off contact, a spring-damper
// force proportional to penetration on contact, whether the contact comes
// from a probe another process moves or from the simulated arm's tip.
#include <cmath>

#include <poll.h>
#include <unistd.h>

#include "chimera/chimera.h"
#include "dev_fixture.hpp"

namespace {

using chm::test::SimDirTest;

class Ft : public SimDirTest {};

TEST_F(Ft, ProbeReadsZeroOffContactAndForceProportionalToPenetration) {
    chm_sim_ft_config_t c;
    chm_sim_ft_config_init(&c);
    c.surface_z = 0.1;
    c.contact_k = 2000.0;
    c.contact_c = 10.0;
    ASSERT_EQ(chm_sim_ft_create(path("ft0").c_str(), &c), 0);
    reg("ft0", "ft0");
    const int sd = chm_sensor_open("ft0");
    ASSERT_GE(sd, 0);
    chm_sio_info_t info;
    ASSERT_EQ(chm_sensor_info(sd, &info), 0);
    ASSERT_EQ(info.n, 6u);
    EXPECT_STREQ(info.name[2], "Fz");
    EXPECT_STREQ(info.unit[2], "N");
    EXPECT_STREQ(info.unit[5], "N*m");
    EXPECT_EQ(chm_actuator_open("ft0", nullptr), CHM_EDEV_ACCES);  // a sensor only

    chm_sim_t* s = nullptr;
    ASSERT_EQ(chm_sim_attach(path("ft0").c_str(), &s), 0);
    chm_sensor_sample_t smp;
    const double above[3] = {0.3, 0.0, 0.5};
    ASSERT_EQ(chm_sim_ft_set_probe(s, above, nullptr), 0);
    ASSERT_EQ(chm_sensor_read(sd, &smp), 0);
    for (int i = 0; i < 6; ++i) EXPECT_EQ(smp.v[i], 0.0) << i;
    const double touching[3] = {0.3, 0.0, 0.1};
    ASSERT_EQ(chm_sim_ft_set_probe(s, touching, nullptr), 0);
    ASSERT_EQ(chm_sensor_read(sd, &smp), 0);
    EXPECT_EQ(smp.v[2], 0.0);

    for (double d : {0.0005, 0.001, 0.002, 0.005}) {
        const double pos[3] = {0.3, 0.0, 0.1 - d};
        ASSERT_EQ(chm_sim_ft_set_probe(s, pos, nullptr), 0);
        ASSERT_EQ(chm_sensor_read(sd, &smp), 0);
        EXPECT_NEAR(smp.v[2], 2000.0 * d, 1e-9) << "penetration " << d;
        EXPECT_EQ(smp.v[0], 0.0);
        EXPECT_EQ(smp.v[5], 0.0);
    }
    // The damper: pressing in adds c*v; pulling out fast never pulls.
    const double pos[3] = {0.3, 0.0, 0.099};
    const double in[3] = {0, 0, -0.2}, out[3] = {0, 0, 5.0};
    ASSERT_EQ(chm_sim_ft_set_probe(s, pos, in), 0);
    ASSERT_EQ(chm_sensor_read(sd, &smp), 0);
    EXPECT_NEAR(smp.v[2], 2000.0 * 0.001 + 10.0 * 0.2, 1e-9);
    ASSERT_EQ(chm_sim_ft_set_probe(s, pos, out), 0);
    ASSERT_EQ(chm_sensor_read(sd, &smp), 0);
    EXPECT_EQ(smp.v[2], 0.0);
    chm_sim_detach(s);
    EXPECT_EQ(chm_dev_close(sd), 0);
}

// Another process moves the probe into the surface: the RTPU sees the force
// and its device's line is raised at the onset of contact.
TEST_F(Ft, ProbeMovedByAnotherProcessRaisesTheLine) {
    chm_sim_ft_config_t c;
    chm_sim_ft_config_init(&c);
    c.contact_k = 1000.0;
    ASSERT_EQ(chm_sim_ft_create(path("ft0").c_str(), &c), 0);
    reg("ft0", "ft0");
    const int sd = chm_sensor_open("ft0");
    ASSERT_GE(sd, 0);
    const int ev = chm_dev_event_fd(sd);
    ASSERT_GE(ev, 0);
    chm::test::drain(ev);
    const std::string file = path("ft0");
    const pid_t child = spawn_child([&] {
        chm_sim_t* s = nullptr;
        if (chm_sim_attach(file.c_str(), &s) < 0) return 1;
        const double p[3] = {0.0, 0.0, -0.004};
        const int r = chm_sim_ft_set_probe(s, p, nullptr);
        chm_sim_detach(s);
        return r == 0 ? 0 : 2;
    });
    ASSERT_EQ(wait_child(child), 0);
    EXPECT_TRUE(chm::test::readable_within(ev, 5000));
    chm_sensor_sample_t smp;
    ASSERT_EQ(chm_sensor_read(sd, &smp), 0);
    EXPECT_NEAR(smp.v[2], 4.0, 1e-9);
    EXPECT_EQ(chm_dev_close(sd), 0);
}

// Mounted on a one-link arm that falls onto a surface below its pivot: off
// contact the sensor reads zero; at rest on the surface the force is the
// spring's k * penetration and balances gravity's moment about the pivot
// (F * l cos th = m g c cos th, so F = m g c / l, whatever the angle).
TEST_F(Ft, OnTheArmReadsTheContactThatHoldsItUp) {
    chm_sim_arm_config_t a;
    chm_sim_arm_config_init(&a, 1);
    a.clock = CHM_SIM_CLOCK_MANUAL;
    a.length[0] = 1.0;
    a.com[0] = 0.5;
    a.mass[0] = 1.0;
    a.inertia[0] = 1.0 / 12.0;
    a.friction[0] = 1.0;
    a.contact = 1;
    a.surface_z = -0.5;
    ASSERT_EQ(chm_sim_arm_create(path("arm0").c_str(), &a), 0);
    chm_sim_ft_config_t c;
    chm_sim_ft_config_init(&c);
    snprintf(c.arm_path, sizeof c.arm_path, "%s", path("arm0").c_str());
    ASSERT_EQ(chm_sim_ft_create(path("ft0").c_str(), &c), 0);
    reg("arm0", "arm0");
    reg("ft0", "ft0");
    const int ft = chm_sensor_open("ft0");
    const int arm = chm_sensor_open("arm0");
    ASSERT_GE(ft, 0);
    ASSERT_GE(arm, 0);
    chm_sio_info_t info;
    ASSERT_EQ(chm_sensor_info(ft, &info), 0);
    EXPECT_EQ(info.time_domain, uint32_t(CHM_TIME_SIM));
    const int ev = chm_dev_event_fd(ft);
    ASSERT_GE(ev, 0);
    chm::test::drain(ev);

    chm_sensor_sample_t f, q;
    ASSERT_EQ(chm_sensor_read(ft, &f), 0);
    EXPECT_EQ(f.v[2], 0.0) << "off contact";
    uint64_t steps = 100;  // 50 ms: still falling, above the surface
    ASSERT_EQ(chm_dev_ioctl(arm, CHM_SIM_IOC_STEP, &steps), 0);
    chm::test::drain(ev);
    ASSERT_EQ(chm_sensor_read(ft, &f), 0);
    EXPECT_EQ(f.v[2], 0.0);
    steps = 8000;  // 4 s: falls, hits, bounces, settles
    ASSERT_EQ(chm_dev_ioctl(arm, CHM_SIM_IOC_STEP, &steps), 0);
    EXPECT_TRUE(chm::test::readable_within(ev, 1000)) << "contact onset raises the line";
    ASSERT_EQ(chm_sensor_read(ft, &f), 0);
    ASSERT_EQ(chm_sensor_read(arm, &q), 0);
    EXPECT_EQ(f.t_ns, q.t_ns);
    EXPECT_LT(std::fabs(q.v[1]), 1e-4) << "at rest";
    const double tip_z = std::sin(q.v[0]);
    const double pen = -0.5 - tip_z;
    EXPECT_GT(pen, 0.0);
    EXPECT_NEAR(f.v[2], 1e4 * pen, 1e-3) << "spring force = k * penetration";
    EXPECT_NEAR(f.v[2], 1.0 * 9.81 * 0.5 / 1.0, 1e-3) << "contact holds the link up";
    EXPECT_EQ(chm_dev_close(ft), 0);
    EXPECT_EQ(chm_dev_close(arm), 0);
}

}  // namespace

// Interrupts from a simulated device wake a task: the sensor's event
// descriptor is bound to IRQ line 40; another process presses the probe;
// the handler drains the line and Vs the semaphore a task waits on, and the
// task reads the contact force.
chm_sem_t g_contact;
int g_ev = -1, g_sd = -1;
double g_fz = -1;
int g_p_result = 1;

TEST_F(Ft, ContactInterruptWakesATask) {
    chm_sim_ft_config_t c;
    chm_sim_ft_config_init(&c);
    c.contact_k = 1000.0;
    ASSERT_EQ(chm_sim_ft_create(path("ft0").c_str(), &c), 0);
    reg("ft0", "ft0");
    const std::string file = path("ft0");
    const pid_t child = spawn_child([&] {  // forked before the kernel starts
        usleep(100000);
        chm_sim_t* s = nullptr;
        if (chm_sim_attach(file.c_str(), &s) < 0) return 1;
        const double p[3] = {0.0, 0.0, -0.004};
        const int r = chm_sim_ft_set_probe(s, p, nullptr);
        chm_sim_detach(s);
        return r == 0 ? 0 : 2;
    });
    chm_kernel_config_t cfg;
    chm_kernel_config_init(&cfg);
    ASSERT_EQ(chm_kernel_init(&cfg), 0);
    g_sd = chm_sensor_open("ft0");
    ASSERT_GE(g_sd, 0);
    g_ev = chm_dev_event_fd(g_sd);
    ASSERT_GE(g_ev, 0);
    chm::test::drain(g_ev);
    ASSERT_EQ(chm_sem_init(&g_contact, CHM_SEM_COUNTING, 0, 0), 0);
    ASSERT_EQ(chm_irq_install(40, [](int, void*) {
        chm::test::drain(g_ev);  // level-triggered: consume what raised the line
        (void)chm_sem_v(&g_contact);
    }, nullptr), 0);
    ASSERT_EQ(chm_irq_attach_fd(40, g_ev, POLLIN), 0);
    chm_tid_t t;
    ASSERT_EQ(chm_task_spawn(&t, [](void*) {
        g_p_result = chm_sem_p_timed(&g_contact, 10000000000ull);
        chm_sensor_sample_t smp;
        if (g_p_result == 0 && chm_sensor_read(g_sd, &smp) == 0) g_fz = smp.v[2];
    }, nullptr, nullptr), 0);
    EXPECT_EQ(chm_kernel_run(), 0);
    (void)chm_irq_detach_fd(40);
    (void)chm_irq_remove(40);
    (void)chm_dev_close(g_sd);
    chm_kernel_fini();
    ASSERT_EQ(wait_child(child), 0);
    EXPECT_EQ(g_p_result, 0) << "no interrupt woke the task";
    EXPECT_NEAR(g_fz, 4.0, 1e-9);
}
