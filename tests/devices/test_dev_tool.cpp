// chimera-sim, run as a separate program, creates, drives and watches the
// devices this RTPU uses through levels 1 and 2.
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "dev_fixture.hpp"

namespace {

using chm::test::SimDirTest;

class Tool : public SimDirTest {
protected:
    // Run chimera-sim with `args`; its stdout (and stderr, with_stderr),
    // and its exit status in *rc.
    std::string run(std::vector<std::string> args, int* rc = nullptr, bool with_stderr = false) {
        const char* tool = std::getenv("CHIMERA_SIM_TOOL");
        if (!tool) {
            ADD_FAILURE() << "CHIMERA_SIM_TOOL not set (run through meson test)";
            return "";
        }
        int fds[2];
        if (pipe(fds) != 0) return "";
        // CHIMERA_SIM_TOOL may be an emulator command line (cross builds):
        // split it on spaces into argv words.
        std::vector<std::string> cmd;
        for (std::string t = tool; !t.empty();) {
            const size_t sp = t.find(' ');
            if (sp) cmd.push_back(t.substr(0, sp));
            t = sp == std::string::npos ? "" : t.substr(sp + 1);
        }
        cmd.push_back("--dir");
        cmd.push_back(dir_);
        args.insert(args.begin(), cmd.begin(), cmd.end());
        const pid_t p = spawn_child([&] {
            dup2(fds[1], 1);
            if (with_stderr) dup2(fds[1], 2);
            close(fds[0]);
            std::vector<char*> argv;
            for (std::string& a : args) argv.push_back(a.data());
            argv.push_back(nullptr);
            execv(argv[0], argv.data());
            return 127;
        });
        close(fds[1]);
        std::string out;
        char buf[512];
        while (chm::test::readable_within(fds[0], 20000)) {
            const ssize_t n = read(fds[0], buf, sizeof buf);
            if (n <= 0) break;
            out.append(buf, size_t(n));
        }
        close(fds[0]);
        const int st = wait_child(p);
        if (rc) *rc = st;
        else EXPECT_EQ(st, 0) << "chimera-sim failed";
        return out;
    }
    // The value of key=... in a line of chimera-sim output.
    static std::string field(const std::string& line, const std::string& key) {
        const size_t at = line.find(" " + key + "=");
        const size_t from = at == std::string::npos ? (line.rfind(key + "=", 0) == 0 ? 0 : std::string::npos)
                                                    : at + 1;
        if (from == std::string::npos) return "";
        const size_t v = from + key.size() + 1;
        return line.substr(v, line.find_first_of(" \n", v) - v);
    }
};

TEST_F(Tool, DrivesTheAdcTheRtpuReads) {
    run({"adc", "create", "adc0", "--in", "2", "--out", "1", "--bits", "8", "--min", "0", "--max", "10"});
    reg("adc0", "adc0");
    const int sd = chm_sensor_open("adc0");
    ASSERT_GE(sd, 0);
    run({"adc", "set", "adc0", "1", "6.5"});
    chm_sensor_sample_t s;
    ASSERT_EQ(chm_sensor_read(sd, &s), 0);
    EXPECT_DOUBLE_EQ(s.v[1], 166 * 10.0 / 255);  // round(6.5 / 10 * 255) = 166
    const int ad = chm_actuator_open("adc0", nullptr);
    ASSERT_GE(ad, 0);
    const double v = 2.5;
    ASSERT_EQ(chm_actuator_write(ad, &v, 1), 0);
    const std::string line = run({"adc", "get", "adc0"});
    EXPECT_EQ(field(line, "out_code"), "64") << line;  // round(63.75)
    EXPECT_EQ(field(line, "in_code"), "0,166") << line;
    int rc = 0;
    run({"adc", "set", "adc0", "9", "1.0"}, &rc);
    EXPECT_NE(rc, 0) << "no channel 9";
    EXPECT_EQ(chm_dev_close(ad), 0);
    EXPECT_EQ(chm_dev_close(sd), 0);
}

TEST_F(Tool, StepsAndWatchesTheArmTheRtpuCommands) {
    run({"arm", "create", "arm0", "--joints", "2", "--clock", "manual", "--gravity", "0"});
    reg("arm0", "arm0");
    const int ad = chm_actuator_open("arm0", nullptr);
    ASSERT_GE(ad, 0);
    const int sd = chm_sensor_open("arm0");
    ASSERT_GE(sd, 0);
    const double tau[2] = {0.5, -0.25};
    ASSERT_EQ(chm_actuator_write(ad, tau, 2), 0);
    run({"arm", "step", "arm0", "100"});
    chm_sensor_sample_t s;
    ASSERT_EQ(chm_sensor_read(sd, &s), 0);
    EXPECT_EQ(s.t_ns, 50000000u) << "100 steps of 0.5 ms, taken by the tool";
    const std::string line = run({"arm", "watch", "arm0", "--count", "2", "--interval-ms", "1"});
    const size_t nl = line.find('\n');
    ASSERT_NE(nl, std::string::npos);
    EXPECT_EQ(field(line, "t"), "0.050000") << line;
    EXPECT_EQ(field(line, "tau"), "0.5,-0.25") << line;
    char q[64];
    snprintf(q, sizeof q, "%.9g,%.9g", s.v[0], s.v[1]);
    EXPECT_EQ(field(line, "q"), q) << line;
    EXPECT_NE(line.find('\n', nl + 1), std::string::npos) << "two readings";
    // The tool's safe stop reaches the RTPU's actuator.
    run({"arm", "stop", "arm0"});
    EXPECT_EQ(chm_actuator_write(ad, tau, 2), -ESHUTDOWN);
    EXPECT_EQ(chm_dev_close(ad), 0);
    EXPECT_EQ(chm_dev_close(sd), 0);
}

TEST_F(Tool, PressesTheProbeAndNamesTheSerialPeer) {
    run({"ft", "create", "ft0", "--surface", "0.2", "--k", "1000"});
    run({"serial", "create", "tty0"});
    reg("ft0", "ft0");
    reg("tty0", "tty0");
    const int sd = chm_sensor_open("ft0");
    ASSERT_GE(sd, 0);
    run({"ft", "probe", "ft0", "0", "0", "0.19"});
    chm_sensor_sample_t s;
    ASSERT_EQ(chm_sensor_read(sd, &s), 0);
    EXPECT_NEAR(s.v[2], 10.0, 1e-9);
    const int tty = chm_dev_open("tty0", CHM_DEV_READ);
    ASSERT_GE(tty, 0);
    char peer[CHM_SIM_PATH_MAX];
    ASSERT_EQ(chm_dev_ioctl(tty, CHM_SERIAL_IOC_PEER_NAME, peer), 0);
    EXPECT_EQ(run({"serial", "peer", "tty0"}), std::string(peer) + "\n");
    const std::string list = run({"list"});
    EXPECT_NE(list.find("ft0 ft\n"), std::string::npos) << list;
    EXPECT_NE(list.find("tty0 serial\n"), std::string::npos) << list;
    EXPECT_EQ(chm_dev_close(tty), 0);
    EXPECT_EQ(chm_dev_close(sd), 0);
}

TEST_F(Tool, GivesTheArmAGripperAndAnObjectOnItsSurface) {
    run({"arm", "create", "arm1", "--clock", "manual", "--surface", "-0.3", "--gripper", "--object", "0.65"});
    std::string line = run({"arm", "get", "arm1"});
    EXPECT_EQ(field(line, "grip"), "0.0800") << "jaws open at start: " << line;
    EXPECT_EQ(field(line, "held"), "0") << line;
    EXPECT_EQ(field(line, "object"), "0.65,-0.3") << "resting on the surface at x: " << line;
    run({"arm", "grip", "arm1", "0.03"});
    run({"arm", "step", "arm1", "2000"});
    line = run({"arm", "get", "arm1"});
    EXPECT_NEAR(std::stod(field(line, "grip")), 0.03, 1e-3) << "the jaws follow the command: " << line;
    EXPECT_EQ(field(line, "held"), "0") << "the tip is nowhere near the object: " << line;
    EXPECT_EQ(field(line, "object"), "0.65,-0.3") << line;
}

TEST_F(Tool, RefusesABadValueNamingItAndCreatesNothing) {
    struct Case {
        std::vector<std::string> args;
        const char* says;
    } cases[] = {
        {{"arm", "create", "bad", "--object", "0.5"}, "--object needs --surface"},
        {{"arm", "create", "bad", "--surface", "-0.3", "--object", "abc"}, "--object: \"abc\" is not a number"},
        {{"arm", "create", "bad", "--q0", "0.1,x"}, "--q0: \"x\" is not a number"},
        {{"arm", "create", "bad", "--clock", "sundial"}, "--clock: \"sundial\""},
        {{"adc", "create", "bad", "--bits", "40"}, "--bits: \"40\" is not a whole number"},
    };
    for (const Case& c : cases) {
        int rc = 0;
        const std::string out = run(c.args, &rc, true);
        EXPECT_EQ(rc, 2) << out;
        EXPECT_NE(out.find(std::string("chimera-sim: ") + c.says), std::string::npos) << out;
        EXPECT_NE(::access((dir_ + "/bad").c_str(), F_OK), 0) << "created anyway: " << c.args[3];
    }
    run({"arm", "create", "arm2", "--clock", "manual"});
    int rc = 0;
    const std::string out = run({"arm", "step", "arm2", "-3"}, &rc, true);
    EXPECT_EQ(rc, 2) << out;
    EXPECT_NE(out.find("steps: \"-3\""), std::string::npos) << out;
    EXPECT_EQ(field(run({"arm", "get", "arm2"}), "t"), "0.000000") << "the arm did not move";
}

}  // namespace
