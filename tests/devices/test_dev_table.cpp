// Level 1: the driver table and descriptors refuse every bad use with a
// status that names the problem, and never reach the driver with it. The
// driver here is a real one (a 64-byte register file), not a mock.
#include <gtest/gtest.h>

#include <cstring>
#include <string>

#include "chimera/chimera.h"
#include "chimera/dev.h"
#include "chimera/err.h"
#include "chimera/sensor.h"

namespace {

struct RegFile {
    unsigned char regs[64] = {};
    int opens = 0, closes = 0, calls = 0;
};
struct RegInst {
    RegFile* f;
};

int rf_open(void* ctx, int, void** inst, uint64_t* range) {
    auto* f = static_cast<RegFile*>(ctx);
    f->opens++;
    *inst = new RegInst{f};
    *range = sizeof f->regs;
    return 0;
}
int rf_close(void* inst) {
    auto* i = static_cast<RegInst*>(inst);
    i->f->closes++;
    delete i;
    return 0;
}
int64_t rf_read(void* inst, void* buf, size_t n, uint64_t off) {
    auto* f = static_cast<RegInst*>(inst)->f;
    f->calls++;
    EXPECT_LE(off + n, sizeof f->regs) << "level 1 let an out-of-range read through";
    std::memcpy(buf, f->regs + off, n);
    return int64_t(n);
}
int64_t rf_write(void* inst, const void* buf, size_t n, uint64_t off) {
    auto* f = static_cast<RegInst*>(inst)->f;
    f->calls++;
    EXPECT_LE(off + n, sizeof f->regs);
    std::memcpy(f->regs + off, buf, n);
    return int64_t(n);
}
int rf_ioctl(void* inst, unsigned long req, void* arg) {
    auto* f = static_cast<RegInst*>(inst)->f;
    f->calls++;
    if (req == 0x8001) {  // private: sum of the registers
        int s = 0;
        for (unsigned char c : f->regs) s += c;
        *static_cast<int*>(arg) = s;
        return 0;
    }
    return CHM_EDEV_NOTTY;
}
const chm_dev_ops_t kRegOps = {rf_open, rf_close, rf_read, rf_write, rf_ioctl, nullptr, nullptr};

class DevTable : public ::testing::Test {
protected:
    void SetUp() override {
        before_ = chm_dev_open_count();
        ASSERT_EQ(chm_dev_register("regs0", &kRegOps, &file_), 0);
    }
    void TearDown() override {
        EXPECT_EQ(chm_dev_unregister("regs0"), 0);
        EXPECT_EQ(chm_dev_open_count(), before_);
        EXPECT_EQ(file_.opens, file_.closes);
    }
    bool last_error_mentions(const char* what) {
        return std::strstr(chm_dev_last_error(), what) != nullptr;
    }
    RegFile file_;
    int before_ = 0;
};

TEST_F(DevTable, OpenByNameReadWriteSeek) {
    const int dd = chm_dev_open("regs0", CHM_DEV_RDWR);
    ASSERT_GE(dd, 256);
    EXPECT_STREQ(chm_dev_name(dd), "regs0");
    const char msg[] = "hello";
    EXPECT_EQ(chm_dev_write(dd, msg, 5), 5);
    EXPECT_EQ(chm_dev_lseek(dd, 0, SEEK_CUR), 5);
    EXPECT_EQ(chm_dev_lseek(dd, 0, SEEK_SET), 0);
    char buf[8] = {};
    EXPECT_EQ(chm_dev_read(dd, buf, 5), 5);
    EXPECT_STREQ(buf, "hello");
    EXPECT_EQ(chm_dev_pread(dd, buf, 2, 1), 2);
    EXPECT_EQ(std::string(buf, 2), "el");
    int sum = 0;
    EXPECT_EQ(chm_dev_ioctl(dd, 0x8001, &sum), 0);
    EXPECT_EQ(sum, 'h' + 'e' + 'l' + 'l' + 'o');
    EXPECT_EQ(chm_dev_close(dd), 0);
}

TEST_F(DevTable, UnknownNameIsRefusedAndNamed) {
    EXPECT_EQ(chm_dev_open("arm9", CHM_DEV_READ), CHM_EDEV_NODEV);
    EXPECT_TRUE(last_error_mentions("no device named \"arm9\"")) << chm_dev_last_error();
    EXPECT_EQ(chm_dev_open(nullptr, CHM_DEV_READ), CHM_EDEV_INVAL);
    EXPECT_EQ(chm_dev_open("regs0", 0), CHM_EDEV_INVAL);       // no direction
    EXPECT_EQ(chm_dev_open("regs0", 0x100), CHM_EDEV_INVAL);   // unknown flag
    EXPECT_EQ(file_.opens, 0);
}

TEST_F(DevTable, BadIoctlIsRefusedAndNamed) {
    const int dd = chm_dev_open("regs0", CHM_DEV_READ);
    ASSERT_GE(dd, 0);
    EXPECT_EQ(chm_dev_ioctl(dd, 0x8999, nullptr), CHM_EDEV_NOTTY);
    EXPECT_TRUE(last_error_mentions("regs0: unknown ioctl request 0x8999")) << chm_dev_last_error();
    EXPECT_EQ(chm_dev_event_fd(dd), CHM_EDEV_NOTTY);  // this device raises no line
    EXPECT_EQ(chm_dev_close(dd), 0);
}

TEST_F(DevTable, ReadPastRangeIsRefusedCrossingIsCut) {
    const int dd = chm_dev_open("regs0", CHM_DEV_RDWR);
    ASSERT_GE(dd, 0);
    char buf[16];
    const int calls = file_.calls;
    EXPECT_EQ(chm_dev_pread(dd, buf, 1, 64), CHM_EDEV_RANGE);
    EXPECT_TRUE(last_error_mentions("offset 64 is past the end of its range (64 bytes)")) << chm_dev_last_error();
    EXPECT_EQ(chm_dev_pwrite(dd, buf, 1, 1000), CHM_EDEV_RANGE);
    EXPECT_EQ(file_.calls, calls) << "an out-of-range access reached the driver";
    EXPECT_EQ(chm_dev_pread(dd, buf, 16, 60), 4);  // crosses the end: cut short
    EXPECT_EQ(chm_dev_lseek(dd, 65, SEEK_SET), CHM_EDEV_RANGE);
    EXPECT_EQ(chm_dev_lseek(dd, -1, SEEK_SET), CHM_EDEV_RANGE);
    EXPECT_EQ(chm_dev_lseek(dd, 0, SEEK_END), 64);
    EXPECT_EQ(chm_dev_read(dd, buf, 1), CHM_EDEV_RANGE);  // at the end
    EXPECT_EQ(chm_dev_lseek(dd, 0, 42), CHM_EDEV_INVAL);
    EXPECT_EQ(chm_dev_close(dd), 0);
}

TEST_F(DevTable, DirectionAndUnsupportedOps) {
    const int dd = chm_dev_open("regs0", CHM_DEV_READ);
    ASSERT_GE(dd, 0);
    char c = 'x';
    EXPECT_EQ(chm_dev_write(dd, &c, 1), CHM_EDEV_ACCES);
    EXPECT_TRUE(last_error_mentions("not opened for writing")) << chm_dev_last_error();
    void* p = nullptr;
    EXPECT_EQ(chm_dev_mmap(dd, 0, 8, CHM_DEV_PROT_READ, &p), CHM_EDEV_NOTSUP);
    EXPECT_EQ(chm_dev_read(dd, nullptr, 1), CHM_EDEV_INVAL);
    chm_sio_info_t info;
    EXPECT_EQ(chm_sensor_info(dd, &info), CHM_ESIO_NOTSUP);  // not a sensor
    EXPECT_EQ(chm_actuator_write(dd, nullptr, 0), CHM_ESIO_NOTSUP);
    EXPECT_EQ(chm_dev_close(dd), 0);
    // Level 2 opens of a device that is neither leave nothing open.
    const int before = chm_dev_open_count();
    EXPECT_EQ(chm_sensor_open("regs0"), CHM_ESIO_NOTSUP);
    EXPECT_EQ(chm_actuator_open("regs0", nullptr), CHM_ESIO_NOTSUP);
    EXPECT_EQ(chm_dev_open_count(), before);
}

TEST_F(DevTable, DoubleCloseAndStaleDescriptorsAreRefused) {
    const int dd = chm_dev_open("regs0", CHM_DEV_RDWR);
    ASSERT_GE(dd, 0);
    EXPECT_EQ(chm_dev_close(dd), 0);
    EXPECT_EQ(file_.closes, 1);
    EXPECT_EQ(chm_dev_close(dd), CHM_EDEV_BADF);
    EXPECT_TRUE(last_error_mentions("is not open (closed, stale or never issued)")) << chm_dev_last_error();
    EXPECT_EQ(file_.closes, 1) << "the driver was closed twice";
    // The slot is reused by the next open, with a new generation: the old
    // descriptor stays dead and cannot touch the new owner's device.
    const int dd2 = chm_dev_open("regs0", CHM_DEV_RDWR);
    ASSERT_GE(dd2, 0);
    EXPECT_EQ(dd2 & 0xff, dd & 0xff) << "expected the freed slot to be reused";
    EXPECT_NE(dd2, dd);
    char c = 0;
    const int calls = file_.calls;
    EXPECT_EQ(chm_dev_read(dd, &c, 1), CHM_EDEV_BADF);
    EXPECT_EQ(chm_dev_ioctl(dd, 0x8001, &c), CHM_EDEV_BADF);
    EXPECT_EQ(chm_dev_close(dd), CHM_EDEV_BADF);
    EXPECT_EQ(file_.calls, calls);
    // Never-issued descriptors, including UNIX fds passed by mistake.
    for (int bogus : {-1, 0, 1, 2, 3, 255, 0x7fffffff})
        EXPECT_EQ(chm_dev_read(bogus, &c, 1), CHM_EDEV_BADF) << bogus;
    EXPECT_EQ(chm_dev_close(dd2), 0);
}

TEST_F(DevTable, RegistrationErrors) {
    EXPECT_EQ(chm_dev_register("regs0", &kRegOps, &file_), CHM_EDEV_EXIST);
    EXPECT_EQ(chm_dev_register("", &kRegOps, &file_), CHM_EDEV_INVAL);
    EXPECT_EQ(chm_dev_register("x", nullptr, nullptr), CHM_EDEV_INVAL);
    const chm_dev_ops_t no_open = {nullptr, rf_close, nullptr, nullptr, nullptr, nullptr, nullptr};
    EXPECT_EQ(chm_dev_register("x", &no_open, nullptr), CHM_EDEV_INVAL);
    EXPECT_EQ(chm_dev_register(std::string(40, 'n').c_str(), &kRegOps, &file_), -ENAMETOOLONG);
    EXPECT_EQ(chm_dev_unregister("nothere"), CHM_EDEV_NODEV);
    const int dd = chm_dev_open("regs0", CHM_DEV_READ);
    ASSERT_GE(dd, 0);
    EXPECT_EQ(chm_dev_unregister("regs0"), CHM_EDEV_BUSY);
    EXPECT_EQ(chm_dev_close(dd), 0);
}

TEST_F(DevTable, DescriptorTableFullIsReported) {
    std::vector<int> dds;
    int r;
    while ((r = chm_dev_open("regs0", CHM_DEV_READ)) >= 0) dds.push_back(r);
    EXPECT_EQ(r, CHM_EDEV_MFILE);
    EXPECT_EQ(int(dds.size()), CHM_DEV_MAX_OPEN - before_);
    for (int dd : dds) EXPECT_EQ(chm_dev_close(dd), 0);
}

// Descriptors belong to the task that opened them; aborting the task
// closes them (the hook the error layer calls).
struct AbortCtx {
    int dd_a = -1, dd_b = -1;
    chm_tid_t a = CHM_TID_NONE;
    int closed = -1;
};

TEST_F(DevTable, TaskAbortClosesWhatTheTaskOpened) {
    chm_kernel_config_t cfg;
    chm_kernel_config_init(&cfg);
    cfg.virtual_clock = 1;
    ASSERT_EQ(chm_kernel_init(&cfg), 0);
    AbortCtx ctx;
    const int mine = chm_dev_open("regs0", CHM_DEV_READ);  // main's, not the task's
    ASSERT_GE(mine, 0);
    chm_task_attr_t at;
    chm_task_attr_init(&at);
    at.name = "owner";
    at.priority = 2;
    ASSERT_EQ(chm_task_spawn(&ctx.a, [](void* p) {
        auto* c = static_cast<AbortCtx*>(p);
        c->dd_a = chm_dev_open("regs0", CHM_DEV_READ);
        c->dd_b = chm_dev_open("regs0", CHM_DEV_RDWR);
        (void)chm_task_suspend(chm_task_self());  // until aborted
    }, &ctx, &at), 0);
    at.name = "aborter";
    at.priority = 1;
    chm_tid_t b;
    ASSERT_EQ(chm_task_spawn(&b, [](void* p) {
        auto* c = static_cast<AbortCtx*>(p);
        c->closed = chm_dev_task_abort(c->a);
        (void)chm_task_destroy(c->a);
    }, &ctx, &at), 0);
    EXPECT_EQ(chm_kernel_run(), 0);
    chm_kernel_fini();
    EXPECT_GE(ctx.dd_a, 0);
    EXPECT_GE(ctx.dd_b, 0);
    EXPECT_EQ(ctx.closed, 2);
    char c;
    EXPECT_EQ(chm_dev_read(ctx.dd_a, &c, 1), CHM_EDEV_BADF);
    EXPECT_EQ(chm_dev_read(mine, &c, 1), 1) << "another owner's descriptor was closed";
    EXPECT_EQ(chm_dev_close(mine), 0);
}

// With global error handling on, a refused device call is an error signal
// of module "dev" naming the problem; a handler may continue (the call
// returns its status), and without one the task alone is aborted.
struct ErrCtx {
    int calls = 0, code = 0;
    std::string detail;
    int64_t open_status = 0, read_status = 0;
    int quiet_status = 0;
    bool after_default = false;
};

TEST_F(DevTable, RefusalsAreErrorSignalsWhenGlobalHandlingIsOn) {
    chm_kernel_config_t cfg;
    chm_kernel_config_init(&cfg);
    cfg.virtual_clock = 1;
    ASSERT_EQ(chm_kernel_init(&cfg), 0);
    ASSERT_GT(chm_dev_err_module(), 0);
    ErrCtx ctx;
    chm_task_attr_t at;
    chm_task_attr_init(&at);
    at.priority = 3;
    chm_tid_t t;
    ASSERT_EQ(chm_task_spawn(&t, [](void* p) {
        auto* c = static_cast<ErrCtx*>(p);
        c->quiet_status = chm_dev_open("nodev", CHM_DEV_READ);  // global off: just a status
        (void)chm_err_global(1);
        (void)chm_err_on_module(chm_dev_err_module(), [](const chm_err_info_t* i, void* a) {
            auto* c = static_cast<ErrCtx*>(a);
            c->calls++;
            c->code = i->code;
            c->detail = i->detail ? i->detail : "";
            return CHM_ERR_CONTINUE;
        }, c);
        c->open_status = chm_dev_open("arm9", CHM_DEV_READ);
        const int dd = chm_dev_open("regs0", CHM_DEV_READ);
        char b;
        c->read_status = chm_dev_pread(dd, &b, 1, 64);
        (void)chm_dev_close(dd);
    }, &ctx, &at), 0);
    at.priority = 2;
    ASSERT_EQ(chm_task_spawn(&t, [](void* p) {
        auto* c = static_cast<ErrCtx*>(p);
        (void)chm_err_global(1);
        (void)chm_dev_open("arm9", CHM_DEV_READ);  // no handler: the default aborts this task
        c->after_default = true;
    }, &ctx, &at), 0);
    at.priority = 1;
    int survivor = 0;
    ASSERT_EQ(chm_task_spawn(&t, [](void* p) { *static_cast<int*>(p) = 1; }, &survivor, &at), 0);
    EXPECT_EQ(chm_kernel_run(), 0);
    chm_kernel_fini();
    EXPECT_EQ(ctx.quiet_status, CHM_EDEV_NODEV);
    EXPECT_EQ(ctx.open_status, CHM_EDEV_NODEV);
    EXPECT_EQ(ctx.read_status, CHM_EDEV_RANGE);
    EXPECT_EQ(ctx.calls, 2);
    EXPECT_EQ(ctx.code, ENXIO);
    EXPECT_NE(ctx.detail.find("regs0: offset 64 is past the end"), std::string::npos) << ctx.detail;
    EXPECT_FALSE(ctx.after_default) << "the default handler must abort the task";
    EXPECT_EQ(survivor, 1) << "the RTPU's other tasks keep running";
}

}  // namespace
