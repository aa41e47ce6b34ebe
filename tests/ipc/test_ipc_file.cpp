// The backplane file: creation, atomic publication, validation of bad
// files (every corruption is refused with the field named and nothing
// mapped), joining and leaving, and chimera-bpcheck's verdicts.
#include <fstream>
#include <sstream>

#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include "ipc/backplane/layout.hpp"
#include "ipc_fixture.hpp"

namespace chm::test {
namespace {

using IpcFile = IpcTest;

bool mapped_here(const std::string& path) {
    std::ifstream maps("/proc/self/maps");
    std::stringstream ss;
    ss << maps.rdbuf();
    return ss.str().find(path) != std::string::npos;
}

TEST_F(IpcFile, CreateJoinLeaveRoundTrip) {
    create();
    ASSERT_EQ(chm_bp_join(path_.c_str(), 1, "alpha"), 0) << chm_bp_last_error();
    EXPECT_EQ(chm_bp_self(), 1);
    chm_bp_status_t st;
    ASSERT_EQ(chm_bp_status(&st), 0);
    EXPECT_EQ(st.slots, 8u);
    EXPECT_EQ(st.self, 1);
    EXPECT_EQ(st.slot[1].state, CHM_BP_RUNNING);
    EXPECT_EQ(st.slot[1].kind, CHM_BP_KIND_RTPU);
    EXPECT_EQ(st.slot[1].generation, 1u);
    EXPECT_EQ(st.slot[1].pid, getpid());
    EXPECT_STREQ(st.slot[1].name, "alpha");
    EXPECT_EQ(st.slot[2].state, CHM_BP_FREE);
    EXPECT_GT(st.created_ns, 0u);
    EXPECT_EQ(st.common_free, 256u * 1024 - 64);
    EXPECT_EQ(chm_bp_join(path_.c_str(), 2, nullptr), -EBUSY);  // one attachment per process
    ASSERT_EQ(chm_bp_leave(), 0);
    EXPECT_EQ(chm_bp_leave(), -ENOTCONN);
    EXPECT_EQ(chm_bp_self(), -ENOTCONN);
    EXPECT_FALSE(mapped_here(path_));

    // Rejoining the slot takes the next generation; a host takes the top slot.
    ASSERT_EQ(chm_bp_join(path_.c_str(), 1, nullptr), 0);
    ASSERT_EQ(chm_bp_status(&st), 0);
    EXPECT_EQ(st.slot[1].generation, 2u);
    EXPECT_STREQ(st.slot[1].name, "rtpu1");
    ASSERT_EQ(chm_bp_leave(), 0);
    int slot = -1;
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), "console", &slot), 0);
    EXPECT_EQ(slot, 7);
    ASSERT_EQ(chm_bp_status(&st), 0);
    EXPECT_EQ(st.slot[7].kind, CHM_BP_KIND_HOST);
}

TEST_F(IpcFile, ExitWithoutLeaveLeavesCleanly) {
    create();
    const pid_t c = spawn([&] {
        if (chm_bp_join(path_.c_str(), 4, nullptr)) return 1;
        std::exit(0);  // atexit handlers run: a clean leave, not a death
    });
    ASSERT_EQ(reap(c), 0);
    ASSERT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), 0);
    chm_bp_status_t st;
    ASSERT_EQ(chm_bp_status(&st), 0);
    EXPECT_EQ(st.slot[4].state, CHM_BP_FREE);
    EXPECT_EQ(st.recoveries, 0u);
}

TEST_F(IpcFile, DefaultPathFollowsEnvironment) {
    char buf[256];
    setenv(CHM_BP_ENV, path_.c_str(), 1);
    ASSERT_EQ(chm_bp_default_path(buf, sizeof buf), 0);
    EXPECT_EQ(path_, buf);
    ASSERT_EQ(chm_bp_create(nullptr, nullptr), 0) << chm_bp_last_error();  // full default geometry
    ASSERT_EQ(chm_bp_join(nullptr, 3, nullptr), 0) << chm_bp_last_error();
    EXPECT_EQ(chm_bp_default_path(buf, 4), -ENAMETOOLONG);
    unsetenv(CHM_BP_ENV);
    ASSERT_EQ(chm_bp_default_path(buf, sizeof buf), 0);
    EXPECT_EQ(std::string(buf).rfind("/dev/shm/chimera-", 0), 0u) << buf;
}

TEST_F(IpcFile, BadConfigIsRefusedAndLeavesNothing) {
    chm_bp_config_t c = small_config();
    c.rtpu_slots = 1;
    EXPECT_EQ(chm_bp_create(path_.c_str(), &c), -EINVAL);
    EXPECT_NE(std::strstr(chm_bp_last_error(), "rtpu_slots"), nullptr) << chm_bp_last_error();
    c = small_config();
    c.common_size = 1000;
    EXPECT_EQ(chm_bp_create(path_.c_str(), &c), -EINVAL);
    EXPECT_NE(std::strstr(chm_bp_last_error(), "common_size"), nullptr) << chm_bp_last_error();
    c = small_config();
    c.rtpu_slots = 32;
    c.local_window_size = 256u << 20;  // 8 GiB of windows
    EXPECT_EQ(chm_bp_create(path_.c_str(), &c), -EFBIG);
    EXPECT_TRUE(dir_entries().empty());
    create();
    EXPECT_EQ(chm_bp_create(path_.c_str(), nullptr), -EEXIST);
}

TEST_F(IpcFile, TwoCreatorsRaceOneWinsAndTheFileIsValid) {
    for (int round = 0; round < 10; ++round) {
        unlink(path_.c_str());
        Pipe go;
        std::vector<pid_t> kids;
        for (int k = 0; k < 2; ++k) {
            kids.push_back(spawn([&] {
                if (go.get() < 0) return 99;
                const chm_bp_config_t c = small_config();
                const int r = chm_bp_create(path_.c_str(), &c);
                return r == 0 ? 0 : r == -EEXIST ? 17 : 98;
            }));
        }
        go.put('g');
        go.put('g');
        const int a = reap(kids[0]), b = reap(kids[1]);
        EXPECT_TRUE((a == 0 && b == 17) || (a == 17 && b == 0)) << "round " << round << ": " << a << " " << b;
        EXPECT_EQ(dir_entries(), std::vector<std::string>{"test.bp"});  // no temporary left behind
        ASSERT_EQ(chm_bp_join(path_.c_str(), 1, nullptr), 0) << chm_bp_last_error();
        ASSERT_EQ(chm_bp_leave(), 0);
    }
}

TEST_F(IpcFile, FullDiskFailsAtCreationNotLater) {
    // A file size limit makes posix_fallocate refuse, as a full disk would.
    const pid_t p = spawn([&] {
        signal(SIGXFSZ, SIG_IGN);
        rlimit lim{64 * 1024, 64 * 1024};
        setrlimit(RLIMIT_FSIZE, &lim);
        const chm_bp_config_t c = small_config();  // ~900 KiB
        const int r = chm_bp_create(path_.c_str(), &c);
        if (r == -EFBIG && std::strstr(chm_bp_last_error(), "reserve")) return 0;
        std::fprintf(stderr, "create returned %d: %s\n", r, chm_bp_last_error());
        return 1;
    });
    EXPECT_EQ(reap(p), 0);
    EXPECT_TRUE(dir_entries().empty());
}

struct Corruption {
    const char* what;
    const char* field;  // what the error must name
    void (*apply)(int fd, chm::bp::Header& h);
};

const Corruption kCorruptions[] = {
    {"truncated", "file_size", [](int fd, bp::Header& h) { ASSERT_EQ(ftruncate(fd, h.file_size - 4096), 0); }},
    {"empty", "shorter than a header", [](int fd, bp::Header&) { ASSERT_EQ(ftruncate(fd, 0), 0); }},
    {"bad magic", "header.magic", [](int, bp::Header& h) { h.magic = 0x12345678; }},
    {"other byte order", "byte order", [](int, bp::Header& h) { h.magic = bp::kMagicSwapped; }},
    {"bad version", "header.version", [](int, bp::Header& h) { h.version = 99; }},
    {"region out of range", "regions[common]",
     [](int, bp::Header& h) { h.regions[bp::kRegionCommon].offset = h.file_size; }},
    {"overlapping regions", "overlaps",
     [](int, bp::Header& h) { h.regions[bp::kRegionRegistry].offset = h.regions[bp::kRegionRings].offset; }},
    {"slot count out of range", "rtpu_slots", [](int, bp::Header& h) { h.geo.rtpu_slots = 1000; }},
    {"registry capacity out of range", "registry_capacity", [](int, bp::Header& h) { h.geo.registry_capacity = 0; }},
    {"extended", "file_size", [](int fd, bp::Header& h) { ASSERT_EQ(ftruncate(fd, h.file_size + 4096), 0); }},
};

TEST_F(IpcFile, EveryCorruptionIsRefusedNamingTheFieldAndMapsNothing) {
    for (const Corruption& c : kCorruptions) {
        SCOPED_TRACE(c.what);
        unlink(path_.c_str());
        create();
        const int fd = open(path_.c_str(), O_RDWR);
        ASSERT_GE(fd, 0);
        bp::Header h;
        ASSERT_EQ(pread(fd, &h, sizeof h, 0), ssize_t(sizeof h));
        c.apply(fd, h);
        struct stat sb;
        fstat(fd, &sb);
        if (sb.st_size >= off_t(sizeof h)) {
            ASSERT_EQ(pwrite(fd, &h, sizeof h, 0), ssize_t(sizeof h));
        }
        close(fd);

        EXPECT_EQ(chm_bp_join(path_.c_str(), 1, nullptr), -EBADMSG);
        EXPECT_NE(std::strstr(chm_bp_last_error(), c.field), nullptr) << chm_bp_last_error();
        EXPECT_NE(std::strstr(chm_bp_last_error(), path_.c_str()), nullptr) << chm_bp_last_error();
        EXPECT_FALSE(mapped_here(path_));
        EXPECT_EQ(chm_bp_self(), -ENOTCONN);
        EXPECT_EQ(chm_bp_attach_host(path_.c_str(), nullptr, nullptr), -EBADMSG);

        std::string out;
        EXPECT_EQ(bpcheck(path_, &out), 1) << out;
        EXPECT_NE(out.find(c.field), std::string::npos) << out;
    }
}

TEST_F(IpcFile, JoinErrorsAreClear) {
    EXPECT_EQ(chm_bp_join(path_.c_str(), 1, nullptr), -ENOENT);
    EXPECT_NE(std::strstr(chm_bp_last_error(), path_.c_str()), nullptr);
    create();
    EXPECT_EQ(chm_bp_join(path_.c_str(), 8, nullptr), -ECHRNG);
    EXPECT_EQ(chm_bp_join(path_.c_str(), -1, nullptr), -ECHRNG);
    EXPECT_EQ(chm_bp_join(path_.c_str(), 1, "a-name-that-is-much-longer-than-31"), -ENAMETOOLONG);
    Pipe ready, done;
    const pid_t p = spawn([&] {
        if (chm_bp_join(path_.c_str(), 1, "holder")) return 1;
        ready.put('r');
        done.get(20000);
        return chm_bp_leave();
    });
    ASSERT_EQ(ready.get(), 'r');
    EXPECT_EQ(chm_bp_join(path_.c_str(), 1, nullptr), -EBUSY);  // a live process holds it
    EXPECT_NE(std::strstr(chm_bp_last_error(), "live process"), nullptr) << chm_bp_last_error();
    done.put('d');
    EXPECT_EQ(reap(p), 0);
    EXPECT_EQ(chm_bp_join(path_.c_str(), 1, nullptr), 0) << chm_bp_last_error();
}

TEST_F(IpcFile, BpcheckCleanFileAndUnreadableFile) {
    create();
    std::string out;
    EXPECT_EQ(bpcheck(path_, &out), 0) << out;
    EXPECT_NE(out.find("clean"), std::string::npos) << out;
    EXPECT_NE(out.find("8 slots"), std::string::npos) << out;
    ASSERT_EQ(chm_bp_join(path_.c_str(), 2, nullptr), 0);
    EXPECT_EQ(bpcheck(path_, &out), 0) << out;
    EXPECT_NE(out.find("1 RTPU"), std::string::npos) << out;
    EXPECT_EQ(bpcheck(dir_ + "/missing.bp", &out), 2) << out;
}

// The helper every multi-process test cleans up with: a test that made a
// subdirectory (the console's `ls` test does) left its whole private
// directory behind in /dev/shm, one per run, when it removed files only.
TEST(PrivateDir, RemovesNestedDirectoriesButNotWhatALinkNames) {
    const std::string outside = make_private_dir("chm-outside-");
    const std::string dir = make_private_dir("chm-nested-");
    ASSERT_FALSE(outside.empty() || dir.empty()) << strerror(errno);
    std::ofstream(outside + "/keep") << "x";
    ASSERT_EQ(mkdir((dir + "/sub").c_str(), 0700), 0);
    ASSERT_EQ(mkdir((dir + "/sub/deeper").c_str(), 0700), 0);
    std::ofstream(dir + "/sub/deeper/file") << "x";
    std::ofstream(dir + "/top") << "x";
    ASSERT_EQ(symlink(outside.c_str(), (dir + "/sub/link").c_str()), 0);
    ASSERT_EQ(mkdir((dir + "/shut").c_str(), 0700), 0);
    std::ofstream(dir + "/shut/inside") << "x";
    ASSERT_EQ(chmod((dir + "/shut").c_str(), 0), 0);  // unreadable (to anyone but root)
    // Only a name make_private_dir gives is removed: a wrong path is left alone.
    remove_private_dir(dir + "/sub");
    remove_private_dir("");
    EXPECT_EQ(access((dir + "/sub/deeper/file").c_str(), F_OK), 0) << "a path not made by make_private_dir was removed";
    remove_private_dir(dir);
    EXPECT_NE(access(dir.c_str(), F_OK), 0) << dir << " is still there";
    EXPECT_EQ(access((outside + "/keep").c_str(), F_OK), 0) << "a file reached through a link was removed";
    remove_private_dir(outside);
    EXPECT_NE(access(outside.c_str(), F_OK), 0);
}

}  // namespace
}  // namespace chm::test
