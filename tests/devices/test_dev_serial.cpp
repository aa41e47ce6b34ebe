// The serial port on a pseudo-terminal: a round trip with a program on the
// other end (another process), line settings that the other end sees, and
// the non-blocking and timeout paths.
#include <fcntl.h>
#include <termios.h>

#include <cctype>
#include <cstring>
#include <string>

#include "dev_fixture.hpp"

namespace {

using chm::test::SimDirTest;

class Serial : public SimDirTest {
protected:
    void SetUp() override {
        SimDirTest::SetUp();
        ASSERT_EQ(chm_sim_serial_create(path("tty0").c_str()), 0);
        reg("tty0", "tty0");
    }
    std::string peer(int dd) {
        char name[CHM_SIM_PATH_MAX] = {};
        EXPECT_EQ(chm_dev_ioctl(dd, CHM_SERIAL_IOC_PEER_NAME, name), 0);
        return name;
    }
};

// The other end: read one line, answer it in capitals.
int echo_upper(const std::string& pty) {
    const int fd = open(pty.c_str(), O_RDWR | O_NOCTTY);
    if (fd < 0) return 10;
    std::string line;
    char c;
    while (line.empty() || line.back() != '\n') {
        if (read(fd, &c, 1) != 1) return 11;
        line += c;
    }
    for (char& ch : line) ch = char(std::toupper(static_cast<unsigned char>(ch)));
    if (write(fd, line.data(), line.size()) != ssize_t(line.size())) return 12;
    close(fd);
    return 0;
}

TEST_F(Serial, RoundTripWithAProcessOnTheOtherEnd) {
    const int dd = chm_dev_open("tty0", CHM_DEV_RDWR);
    ASSERT_GE(dd, 0);
    const std::string pty = peer(dd);
    ASSERT_EQ(pty.rfind("/dev/pts/", 0), 0u) << pty;
    // Published in the device's file and as a symlink, for other processes.
    chm_sim_t* s = nullptr;
    ASSERT_EQ(chm_sim_attach(path("tty0").c_str(), &s), 0);
    char published[CHM_SIM_PATH_MAX];
    ASSERT_EQ(chm_sim_serial_peer(s, published, sizeof published), 0);
    chm_sim_detach(s);
    EXPECT_EQ(pty, published);
    char link[256] = {};
    ASSERT_GT(readlink(path("tty0.pty").c_str(), link, sizeof link - 1), 0);
    EXPECT_EQ(pty, link);

    const pid_t child = spawn_child([&] { return echo_upper(pty); });
    const int32_t timeout_ms = 10000;
    ASSERT_EQ(chm_dev_ioctl(dd, CHM_SERIAL_IOC_SET_TIMEOUT, const_cast<int32_t*>(&timeout_ms)), 0);
    const char msg[] = "hello, arm\n";
    ASSERT_EQ(chm_dev_write(dd, msg, sizeof msg - 1), int64_t(sizeof msg - 1));
    std::string got;
    char buf[64];
    while (got.find('\n') == std::string::npos) {
        const int64_t n = chm_dev_read(dd, buf, sizeof buf);
        ASSERT_GT(n, 0) << chm_dev_last_error();
        got.append(buf, size_t(n));
    }
    EXPECT_EQ(got, "HELLO, ARM\n");
    EXPECT_EQ(wait_child(child), 0);
    EXPECT_EQ(chm_dev_close(dd), 0);
}

TEST_F(Serial, LineSettingsAreWhatTheOtherEndSees) {
    const int dd = chm_dev_open("tty0", CHM_DEV_RDWR);
    ASSERT_GE(dd, 0);
    chm_serial_line_t l{};
    ASSERT_EQ(chm_dev_ioctl(dd, CHM_SERIAL_IOC_GET_LINE, &l), 0);
    EXPECT_EQ(l.baud, 115200u);
    EXPECT_EQ(l.data_bits, 8);
    EXPECT_EQ(l.parity, 'N');
    chm_serial_line_t set{9600, 7, 'E', 2, 0};
    ASSERT_EQ(chm_dev_ioctl(dd, CHM_SERIAL_IOC_SET_LINE, &set), 0);
    ASSERT_EQ(chm_dev_ioctl(dd, CHM_SERIAL_IOC_GET_LINE, &l), 0);
    EXPECT_EQ(l.baud, 9600u);
    EXPECT_EQ(l.data_bits, 7);
    EXPECT_EQ(l.parity, 'E');
    EXPECT_EQ(l.stop_bits, 2);
    const std::string pty = peer(dd);
    const pid_t child = spawn_child([&] {
        const int fd = open(pty.c_str(), O_RDWR | O_NOCTTY);
        termios t;
        if (fd < 0 || tcgetattr(fd, &t) != 0) return 10;
        if (cfgetospeed(&t) != B9600) return 11;
        if (!(t.c_cflag & CSTOPB)) return 12;
        // (A Linux pty forces CS8 without parity: not checked here.)
        return 0;
    });
    EXPECT_EQ(wait_child(child), 0);
    chm_serial_line_t bad{12345, 8, 'N', 1, 0};
    EXPECT_EQ(chm_dev_ioctl(dd, CHM_SERIAL_IOC_SET_LINE, &bad), CHM_EDEV_INVAL);
    bad = {9600, 9, 'N', 1, 0};
    EXPECT_EQ(chm_dev_ioctl(dd, CHM_SERIAL_IOC_SET_LINE, &bad), CHM_EDEV_INVAL);
    bad = {9600, 8, 'X', 1, 0};
    EXPECT_EQ(chm_dev_ioctl(dd, CHM_SERIAL_IOC_SET_LINE, &bad), CHM_EDEV_INVAL);
    EXPECT_EQ(chm_dev_close(dd), 0);
}

TEST_F(Serial, NonBlockingTimeoutAndEventFd) {
    const int nb = chm_dev_open("tty0", CHM_DEV_RDWR | CHM_DEV_NONBLOCK);
    ASSERT_GE(nb, 0);
    char buf[8];
    EXPECT_EQ(chm_dev_read(nb, buf, sizeof buf), -EAGAIN);
    EXPECT_EQ(chm_dev_lseek(nb, 0, SEEK_SET), CHM_EDEV_NOTSUP);  // a stream
    const int dd = chm_dev_open("tty0", CHM_DEV_RDWR);
    ASSERT_GE(dd, 0);
    const int32_t ms = 50;
    ASSERT_EQ(chm_dev_ioctl(dd, CHM_SERIAL_IOC_SET_TIMEOUT, const_cast<int32_t*>(&ms)), 0);
    EXPECT_EQ(chm_dev_read(dd, buf, sizeof buf), -ETIMEDOUT);
    // The event fd becomes readable when the other end writes.
    const int ev = chm_dev_event_fd(dd);
    ASSERT_GE(ev, 0);
    const int fd = open(peer(dd).c_str(), O_RDWR | O_NOCTTY);
    ASSERT_GE(fd, 0);
    EXPECT_FALSE(chm::test::readable_within(ev, 0));
    ASSERT_EQ(write(fd, "x", 1), 1);
    EXPECT_TRUE(chm::test::readable_within(ev, 5000));
    EXPECT_EQ(chm_dev_read(nb, buf, sizeof buf), 1);
    EXPECT_EQ(buf[0], 'x');
    close(fd);
    EXPECT_EQ(chm_dev_close(dd), 0);
    EXPECT_EQ(chm_dev_close(nb), 0);
}

}  // namespace
