// The A/D and D/A converter backed by a shared-memory file: inputs written
// by another process are read with the configured quantisation; outputs
// written by the RTPU are seen by another process; registers by level 1,
// volts by level 2, and a mapping that is the same memory.
#include <cmath>
#include <cstring>

#include "dev_fixture.hpp"

namespace {

using chm::test::SimDirTest;

constexpr double kMax = 5.0;
constexpr uint32_t kBits = 10;
constexpr double kLsb = kMax / 1023.0;

class Adc : public SimDirTest {
protected:
    void SetUp() override {
        SimDirTest::SetUp();
        chm_sim_adc_config_t c;
        chm_sim_adc_config_init(&c);
        c.n_in = 4;
        c.n_out = 2;
        c.bits_in = c.bits_out = kBits;
        c.vmin = 0.0;
        c.vmax = kMax;
        ASSERT_EQ(chm_sim_adc_create(path("adc0").c_str(), &c), 0);
        reg("adc0", "adc0");
        file_ = path("adc0");
    }
    // A child process that attaches and runs fn(sim).
    template <class F> int in_child(F fn) {
        const std::string f = file_;
        const pid_t p = spawn_child([f, fn] {
            chm_sim_t* s = nullptr;
            if (chm_sim_attach(f.c_str(), &s) < 0) return 100;
            const int r = fn(s);
            chm_sim_detach(s);
            return r;
        });
        return wait_child(p);
    }
    std::string file_;
};

TEST_F(Adc, InputsWrittenByAnotherProcessAreReadQuantised) {
    const int sd = chm_sensor_open("adc0");
    ASSERT_GE(sd, 0);
    chm_sio_info_t info;
    ASSERT_EQ(chm_sensor_info(sd, &info), 0);
    EXPECT_EQ(info.n, 4u);
    EXPECT_STREQ(info.name[1], "ai1");
    EXPECT_STREQ(info.unit[1], "V");
    EXPECT_EQ(info.time_domain, uint32_t(CHM_TIME_MONOTONIC));
    const int ev = chm_dev_event_fd(sd);
    ASSERT_GE(ev, 0);
    chm::test::drain(ev);

    ASSERT_EQ(in_child([](chm_sim_t* s) {
        return chm_sim_adc_set_input(s, 1, 3.3) | chm_sim_adc_set_input(s, 2, 7.0) |
               chm_sim_adc_set_input(s, 3, -1.0);
    }), 0);
    EXPECT_TRUE(chm::test::readable_within(ev, 5000)) << "new input raises the line";
    chm_sensor_sample_t smp;
    ASSERT_EQ(chm_sensor_read(sd, &smp), 0);
    ASSERT_EQ(smp.n, 4u);
    EXPECT_EQ(smp.v[0], 0.0);
    const double code = std::nearbyint(3.3 / kLsb);  // 675
    EXPECT_EQ(smp.v[1], code * kLsb) << "quantised to the 10-bit grid";
    EXPECT_NE(smp.v[1], 3.3);
    EXPECT_LE(std::fabs(smp.v[1] - 3.3), kLsb / 2);
    EXPECT_EQ(smp.v[2], kMax) << "above the range: full scale";
    EXPECT_EQ(smp.v[3], 0.0) << "below the range: zero scale";
    // Level 1: the raw codes.
    int32_t codes[4];
    ASSERT_EQ(chm_dev_pread(sd, codes, sizeof codes, 0), int64_t(sizeof codes));
    EXPECT_EQ(codes[1], int32_t(code));
    EXPECT_EQ(codes[2], 1023);
    EXPECT_EQ(chm_dev_pread(sd, codes, 4, 24), CHM_EDEV_RANGE);  // 4 inputs + 2 outputs
    EXPECT_EQ(chm_dev_close(sd), 0);
}

TEST_F(Adc, OutputsAreVisibleToAnotherProcess) {
    const int ad = chm_actuator_open("adc0", nullptr);
    ASSERT_GE(ad, 0);
    const double v[2] = {1.234, 4.0};
    ASSERT_EQ(chm_actuator_write(ad, v, 2), 0);
    const int32_t c0 = int32_t(std::nearbyint(1.234 / kLsb)), c1 = int32_t(std::nearbyint(4.0 / kLsb));
    EXPECT_EQ(in_child([c0, c1](chm_sim_t* s) {
        double x0, x1;
        int32_t k0, k1;
        if (chm_sim_adc_get_output(s, 0, &x0, &k0) || chm_sim_adc_get_output(s, 1, &x1, &k1)) return 1;
        if (k0 != c0 || k1 != c1) return 2;
        // Within rounding, not bit-exact: the 68881 computes in extended precision.
        if (std::fabs(x0 - c0 * kLsb) > 1e-12 || std::fabs(x0 - 1.234) > kLsb / 2) return 3;
        return 0;
    }), 0);
    // Beyond the range: clamped by level 2 and reported.
    const double over[2] = {9.0, 0.0};
    EXPECT_EQ(chm_actuator_write(ad, over, 2), CHM_ACT_CLAMPED);
    EXPECT_EQ(in_child([](chm_sim_t* s) {
        int32_t k;
        return chm_sim_adc_get_output(s, 0, nullptr, &k) == 0 && k == 1023 ? 0 : 1;
    }), 0);
    // Safe stop: the outputs go to 0 V.
    ASSERT_EQ(chm_actuator_stop(ad), 0);
    EXPECT_EQ(in_child([](chm_sim_t* s) {
        int32_t k0, k1;
        chm_sim_adc_get_output(s, 0, nullptr, &k0);
        chm_sim_adc_get_output(s, 1, nullptr, &k1);
        return k0 == 0 && k1 == 0 ? 0 : 1;
    }), 0);
    EXPECT_EQ(chm_dev_close(ad), 0);
}

TEST_F(Adc, RegistersAndMappingAreTheSharedMemory) {
    const int dd = chm_dev_open("adc0", CHM_DEV_RDWR);
    ASSERT_GE(dd, 0);
    const int32_t code = 300;
    EXPECT_EQ(chm_dev_pwrite(dd, &code, 4, 16 + 4), 4);  // output 1
    EXPECT_EQ(chm_dev_pwrite(dd, &code, 4, 0), CHM_EDEV_ACCES);  // inputs are read-only
    const int32_t big = 1024;
    EXPECT_EQ(chm_dev_pwrite(dd, &big, 4, 16), -ERANGE);  // beyond 10 bits
    EXPECT_EQ(chm_dev_pwrite(dd, &code, 2, 16), CHM_EDEV_INVAL);

    void* p = nullptr;
    EXPECT_EQ(chm_dev_mmap(dd, 0, 32, CHM_DEV_PROT_READ, &p), CHM_EDEV_RANGE);
    ASSERT_EQ(chm_dev_mmap(dd, 0, 24, CHM_DEV_PROT_READ | CHM_DEV_PROT_WRITE, &p), 0);
    volatile int32_t* regs = static_cast<int32_t*>(p);
    EXPECT_EQ(regs[5], 300);
    regs[4] = 777;  // output 0, written through the mapping
    EXPECT_EQ(in_child([](chm_sim_t* s) {
        int32_t k;
        chm_sim_adc_get_output(s, 0, nullptr, &k);
        if (k != 777) return 1;
        return chm_sim_adc_set_input(s, 0, 2.5) == 0 ? 0 : 2;
    }), 0);
    EXPECT_EQ(regs[0], int32_t(std::nearbyint(2.5 / kLsb))) << "the child's input, seen in the mapping";
    // A second mapping at an offset; close releases both.
    void* q = nullptr;
    ASSERT_EQ(chm_dev_mmap(dd, 16, 8, CHM_DEV_PROT_READ, &q), 0);
    EXPECT_EQ(static_cast<int32_t*>(q)[0], 777);
    EXPECT_EQ(chm_dev_munmap(dd, q, 8), 0);
    EXPECT_EQ(chm_dev_munmap(dd, q, 8), CHM_EDEV_INVAL);
    EXPECT_EQ(chm_dev_close(dd), 0);

    const int ro = chm_dev_open("adc0", CHM_DEV_READ);
    ASSERT_GE(ro, 0);
    EXPECT_EQ(chm_dev_mmap(ro, 0, 8, CHM_DEV_PROT_WRITE, &p), CHM_EDEV_ACCES);
    EXPECT_EQ(chm_dev_close(ro), 0);
}

}  // namespace
