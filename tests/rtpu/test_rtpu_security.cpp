// Issue 21's attacks, tried for real (SECURITY.md): a backplane that is not
// the caller's to trust (another owner, group- or world-accessible, a
// symbolic link, a FIFO, a directory), a squatted default directory, and
// programs from paths someone else could change. Each is refused by every
// entry point (chimera start / status / stop / rm, chimera-rtpu, a host
// attach, express mail) with a message naming the file, owner, mode and
// fix, and nothing is started. Runs as root here (as CI may): the files of
// "another user" are chowned to nobody; without root those cases skip.
#include <ftw.h>
#include <grp.h>
#include <pwd.h>
#include <sys/stat.h>

#include "rtpu_fixture.hpp"

using namespace chm::test;

namespace {

constexpr uid_t kNobody = 65534;

bool contains(const std::string& s, const std::string& what) { return s.find(what) != std::string::npos; }

// Processes whose command line mentions `needle` (our private directory).
std::vector<pid_t> processes_naming(const std::string& needle) {
    std::vector<pid_t> out;
    DIR* d = opendir("/proc");
    if (!d) return out;
    while (dirent* e = readdir(d)) {
        const pid_t pid = pid_t(std::atoi(e->d_name));
        if (pid <= 0 || pid == getpid()) continue;
        std::string cmd = read_file(std::string("/proc/") + e->d_name + "/cmdline");
        for (char& c : cmd)
            if (c == 0) c = ' ';
        if (contains(cmd, needle)) out.push_back(pid);
    }
    closedir(d);
    return out;
}

// How the messages name this process's user: "root (uid 0)" / "root".
std::string my_name() {
    const passwd* pw = getpwuid(geteuid());
    return pw ? pw->pw_name : "uid " + std::to_string(geteuid());
}
std::string me() { return my_name() + " (uid " + std::to_string(geteuid()) + ")"; }

int remove_entry(const char* path, const struct stat*, int, FTW*) { return ::remove(path) == 0 ? 0 : 0; }

void copy_file(const std::string& from, const std::string& to, mode_t mode) {
    std::ifstream in(from, std::ios::binary);
    std::ofstream(to, std::ios::binary) << in.rdbuf();
    chmod(to.c_str(), mode);
}

class SecurityTest : public RtpuTest {
protected:
    void SetUp() override {
        RtpuTest::SetUp();
        saved_xdg_ = getenv("XDG_RUNTIME_DIR") ? getenv("XDG_RUNTIME_DIR") : "";
        had_xdg_ = getenv("XDG_RUNTIME_DIR") != nullptr;
        unsetenv(CHM_BP_ENV);
    }
    void TearDown() override {
        if (had_xdg_) setenv("XDG_RUNTIME_DIR", saved_xdg_.c_str(), 1);
        else unsetenv("XDG_RUNTIME_DIR");
        // Whatever a failing test left running on our files.
        for (pid_t p : processes_naming(dir_)) kill(p, SIGKILL);
        RtpuTest::TearDown();
        if (!dir_.empty()) nftw(dir_.c_str(), remove_entry, 16, FTW_DEPTH | FTW_PHYS);
    }

    // Everything that opens the backplane at `path` is refused, saying
    // `says`; nothing is started and the file stays.
    void expect_refused_everywhere(const std::string& path, const std::string& says, bool with_backplane = true) {
        auto cmd = [&](std::vector<std::string> args) {
            args.insert(args.begin(), CHIMERA_BIN);
            if (with_backplane) args.insert(args.begin() + 2, {"--backplane", path});
            return run(args);
        };
        struct stat before{};
        ASSERT_EQ(lstat(path.c_str(), &before), 0) << path;
        for (const char* sub : {"start", "status", "stop", "rm"}) {
            std::vector<std::string> args = {sub};
            if (std::string(sub) == "start") args.insert(args.end(), {"--rtpus", "1", "--timeout", "3"});
            const Outcome r = cmd(args);
            EXPECT_EQ(r.status, 1) << sub << ": " << r.out << r.err;
            EXPECT_TRUE(contains(r.err, says)) << sub << ": " << r.err;
            EXPECT_TRUE(contains(r.err, "fix")) << sub << ": " << r.err;
        }
        const Outcome force = cmd({"rm", "--force"});
        EXPECT_EQ(force.status, 1) << force.err;
        EXPECT_TRUE(contains(force.err, says)) << force.err;
        std::vector<std::string> rtpu = {CHIMERA_RTPU_BIN, "--rtpu", "1"};
        if (with_backplane) rtpu.insert(rtpu.end(), {"--backplane", path});
        const Outcome r = run(rtpu);
        EXPECT_EQ(r.status, 1) << r.err;
        EXPECT_TRUE(contains(r.err, says)) << r.err;
        EXPECT_EQ(chm_bp_attach_host(with_backplane ? path.c_str() : nullptr, "intruder", nullptr) < 0, true);
        EXPECT_TRUE(contains(chm_bp_last_error(), says)) << chm_bp_last_error();
        (void)chm_bp_leave();
        EXPECT_TRUE(processes_naming(dir_).empty()) << "something was started on " << path;
        struct stat after{};
        EXPECT_EQ(lstat(path.c_str(), &after), 0) << path << " was removed";
        EXPECT_EQ(after.st_ino, before.st_ino);
        EXPECT_FALSE(exists(path + ".rtpu1.log")) << "a log was made for a refused start";
    }
    static bool exists(const std::string& p) { return access(p.c_str(), F_OK) == 0; }

    // A valid backplane at `path` (root's or ours, mode 0600).
    void make_backplane(const std::string& path, int group = -1) {
        chm_bp_config_t c;
        chm_bp_config_init(&c);
        c.rtpu_slots = 8;
        c.local_window_size = 64 * 1024;
        c.common_size = 256 * 1024;
        c.registry_capacity = 32;
        c.ring_record_size = 1024;
        c.group = group;
        ASSERT_EQ(chm_bp_create(path.c_str(), &c), 0) << chm_bp_last_error();
    }

    std::string saved_xdg_;
    bool had_xdg_ = false;
};

}  // namespace

// ------------------------------------------------------------ who may attach

TEST_F(SecurityTest, AFileOfAnotherOwnerIsRefusedEvenForRoot) {
    if (geteuid() != 0) GTEST_SKIP() << "needs root to give the file to nobody (chown)";
    make_backplane(bp_);
    ASSERT_EQ(chown(bp_.c_str(), kNobody, kNobody), 0) << strerror(errno);
    expect_refused_everywhere(bp_, "owner nobody (uid 65534)");
    EXPECT_EQ(chm_bp_check_file(bp_.c_str()), -EPERM);
    EXPECT_TRUE(contains(chm_bp_last_error(), "mode 0600: not yours (you are " + me() + ")")) << chm_bp_last_error();
}

TEST_F(SecurityTest, WorldAndGroupAccessIsRefused) {
    make_backplane(bp_);
    chmod(bp_.c_str(), 0666);
    expect_refused_everywhere(bp_, "mode 0666: others have access (anyone could change it)");
    chmod(bp_.c_str(), 0604);
    expect_refused_everywhere(bp_, "mode 0604: others have access (anyone could read it)");
    chmod(bp_.c_str(), 0660);  // group-writable, but not made for a group
    expect_refused_everywhere(bp_, "mode 0660: group-writable, but it was not created for that group");
    chmod(bp_.c_str(), 0640);  // group may read: harmless, attaches
    ASSERT_EQ(chm_bp_check_file(bp_.c_str()), 0) << chm_bp_last_error();
}

TEST_F(SecurityTest, AFileMadeForAGroupIsSharedOnlyAsMade) {
    const gid_t g = getegid();
    make_backplane(bp_, int(g));
    struct stat st{};
    ASSERT_EQ(stat(bp_.c_str(), &st), 0);
    EXPECT_EQ(st.st_mode & 07777, 0660u);  // whatever the umask
    EXPECT_EQ(st.st_gid, g);
    ASSERT_EQ(chm_bp_check_file(bp_.c_str()), 0) << chm_bp_last_error();
    const pid_t p = start_rtpu(1);
    ASSERT_EQ(chm_bp_attach_host(bp_.c_str(), "test", nullptr), 0) << chm_bp_last_error();
    EXPECT_TRUE(wait_serving(1, p)) << read_file(err_of(1));
    kill(p, SIGTERM);
    EXPECT_EQ(reap(p), 0);
    (void)chm_bp_leave();
    // Loosened further, or given to another group: refused.
    chmod(bp_.c_str(), 0666);
    expect_refused_everywhere(bp_, "others have access");
    chmod(bp_.c_str(), 0660);
    if (geteuid() == 0) {
        ASSERT_EQ(chown(bp_.c_str(), uid_t(-1), kNobody == g ? 0 : gid_t(kNobody)), 0);
        expect_refused_everywhere(bp_, "not created for that group");
    }
    // A config that attaching would refuse is never made.
    chm_bp_config_t c;
    chm_bp_config_init(&c);
    c.mode = 0660;
    EXPECT_EQ(chm_bp_create((dir_ + "/loose.bp").c_str(), &c), -EINVAL);
    EXPECT_TRUE(contains(chm_bp_last_error(), "attaching would be refused")) << chm_bp_last_error();
    c.mode = 0604;
    EXPECT_EQ(chm_bp_create((dir_ + "/loose.bp").c_str(), &c), -EINVAL);
    EXPECT_FALSE(exists(dir_ + "/loose.bp"));
}

TEST_F(SecurityTest, ASymlinkedBackplaneIsRefused) {
    const std::string real = dir_ + "/real.bp";
    make_backplane(real);
    ASSERT_EQ(symlink(real.c_str(), bp_.c_str()), 0);
    expect_refused_everywhere(bp_, "is a symbolic link (to " + real);
    ASSERT_EQ(chm_bp_check_file(real.c_str()), 0) << chm_bp_last_error();  // the file itself is fine
}

TEST_F(SecurityTest, AFifoOrADirectoryAtThePathIsRefused) {
    ASSERT_EQ(mkfifo(bp_.c_str(), 0600), 0);
    expect_refused_everywhere(bp_, "is a FIFO (owner " + me());
    unlink(bp_.c_str());
    ASSERT_EQ(mkdir(bp_.c_str(), 0700), 0);
    expect_refused_everywhere(bp_, "is a directory (owner " + me());
    if (access("/dev/null", F_OK) == 0) {  // a device
        EXPECT_EQ(chm_bp_check_file("/dev/null"), -EBADMSG);
        EXPECT_TRUE(contains(chm_bp_last_error(), "is a character device")) << chm_bp_last_error();
    }
}

// ------------------------------------------------------- the default path

TEST_F(SecurityTest, TheDefaultPathIsInADirectoryOfTheUsersAlone) {
    const std::string xdg = dir_ + "/xdg";
    ASSERT_EQ(mkdir(xdg.c_str(), 0700), 0);
    setenv("XDG_RUNTIME_DIR", xdg.c_str(), 1);
    char buf[4096];
    ASSERT_EQ(chm_bp_default_path(buf, sizeof buf), 0);
    EXPECT_EQ(std::string(buf), xdg + "/chimera/backplane.bp");
    const Outcome path = run({CHIMERA_BIN, "path"});
    EXPECT_EQ(path.out, xdg + "/chimera/backplane.bp\n");
    // An XDG_RUNTIME_DIR that is not ours (as under sudo) is not used.
    const std::string theirs = dir_ + "/theirs";
    ASSERT_EQ(mkdir(theirs.c_str(), 0700), 0);
    if (geteuid() == 0) {
        ASSERT_EQ(chown(theirs.c_str(), kNobody, kNobody), 0);
        setenv("XDG_RUNTIME_DIR", theirs.c_str(), 1);
        ASSERT_EQ(chm_bp_default_dir(buf, sizeof buf), 0);
        EXPECT_EQ(std::string(buf), "/dev/shm/chimera-" + std::to_string(geteuid()));
    }
    unsetenv("XDG_RUNTIME_DIR");
    ASSERT_EQ(chm_bp_default_path(buf, sizeof buf), 0);
    EXPECT_EQ(std::string(buf), "/dev/shm/chimera-" + std::to_string(geteuid()) + "/backplane.bp");

    // start creates the directory 0700 and the logs 0640, appended.
    setenv("XDG_RUNTIME_DIR", xdg.c_str(), 1);
    const std::string bp = xdg + "/chimera/backplane.bp";
    Outcome r = run({CHIMERA_BIN, "start", "--rtpus", "1"});
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_TRUE(contains(r.out, "on " + bp)) << r.out;
    struct stat st{};
    ASSERT_EQ(lstat((xdg + "/chimera").c_str(), &st), 0);
    EXPECT_TRUE(S_ISDIR(st.st_mode));
    EXPECT_EQ(st.st_mode & 07777, 0700u);
    ASSERT_EQ(lstat((bp + ".rtpu1.log").c_str(), &st), 0);
    EXPECT_EQ(st.st_mode & 07777, 0640u);
    r = run({CHIMERA_BIN, "stop"});
    EXPECT_EQ(r.status, 0) << r.err;
    // A second start on the same backplane appends to the log.
    r = run({CHIMERA_BIN, "start", "--rtpus", "1"});
    ASSERT_EQ(r.status, 0) << r.err;
    r = run({CHIMERA_BIN, "stop"});
    EXPECT_EQ(r.status, 0) << r.err;
    std::string log = read_file(bp + ".rtpu1.log");
    // Each start's mark, joined, stopped; twice: the first run's lines kept.
    EXPECT_EQ(count_lines(log), 6) << log;
    EXPECT_EQ(log.find("chimera start: "), 0u) << log;
    EXPECT_NE(log.find("chimera start: ", 1), std::string::npos) << log;
    // A log that is a symbolic link (to a file someone wants overwritten):
    // the start is refused before any RTPU runs, the target untouched.
    const std::string victim = dir_ + "/victim";
    { std::ofstream(victim) << "precious\n"; }
    unlink((bp + ".rtpu1.log").c_str());
    ASSERT_EQ(symlink(victim.c_str(), (bp + ".rtpu1.log").c_str()), 0);
    r = run({CHIMERA_BIN, "start", "--rtpus", "1"});
    EXPECT_EQ(r.status, 1) << r.out;
    EXPECT_TRUE(contains(r.err, "cannot open the log " + bp + ".rtpu1.log")) << r.err;
    EXPECT_EQ(read_file(victim), "precious\n");
    EXPECT_TRUE(processes_naming(dir_).empty());
    unlink((bp + ".rtpu1.log").c_str());
    r = run({CHIMERA_BIN, "rm"});
    EXPECT_EQ(r.status, 0) << r.err;
    EXPECT_FALSE(exists(bp));
}

TEST_F(SecurityTest, ASquattedDefaultDirectoryIsRefused) {
    const std::string xdg = dir_ + "/xdg";
    const std::string squat = xdg + "/chimera";
    const std::string bp = squat + "/backplane.bp";
    ASSERT_EQ(mkdir(xdg.c_str(), 0700), 0);
    setenv("XDG_RUNTIME_DIR", xdg.c_str(), 1);

    // Mode 0777, holding a backplane planted there.
    ASSERT_EQ(mkdir(squat.c_str(), 0700), 0);
    make_backplane(bp);
    chmod(squat.c_str(), 0777);
    expect_refused_everywhere(bp, "backplane directory " + squat + ": owner " + me() + ", mode 0777: others have access",
                              false);
    // A symbolic link to a directory of ours.
    ASSERT_EQ(rename(squat.c_str(), (xdg + "/elsewhere").c_str()), 0);
    chmod((xdg + "/elsewhere").c_str(), 0700);
    ASSERT_EQ(symlink((xdg + "/elsewhere").c_str(), squat.c_str()), 0);
    expect_refused_everywhere(bp, "backplane directory " + squat + ": is a symbolic link", false);
    unlink(squat.c_str());
    // Another user's, made first.
    if (geteuid() == 0) {
        ASSERT_EQ(rename((xdg + "/elsewhere").c_str(), squat.c_str()), 0);
        ASSERT_EQ(chown(squat.c_str(), kNobody, kNobody), 0);
        expect_refused_everywhere(bp, "backplane directory " + squat + ": owner nobody (uid 65534), mode 0700: not yours",
                                  false);
    }
    // A start with no backplane yet is refused too: nothing is made there.
    nftw(squat.c_str(), remove_entry, 16, FTW_DEPTH | FTW_PHYS);
    ASSERT_EQ(mkdir(squat.c_str(), 0777), 0);
    chmod(squat.c_str(), 0777);
    const Outcome r = run({CHIMERA_BIN, "start", "--rtpus", "1"});
    EXPECT_EQ(r.status, 1) << r.out;
    EXPECT_TRUE(contains(r.err, "mode 0777: others have access")) << r.err;
    EXPECT_TRUE(private_dir_entries(squat).empty());
    EXPECT_TRUE(processes_naming(dir_).empty());
}

// ------------------------------------------------------------ program paths

TEST_F(SecurityTest, ProgramsLoadOnlyFromPathsNoOneElseCanChange) {
    create(false);
    const std::string probe_out = dir_ + "/probe.txt";
    struct Case {
        std::string program;
        std::vector<std::string> extra;
        std::vector<std::string> says;  // empty: loads
    };
    const std::string ww = dir_ + "/ww.so";
    copy_file(PROBE_SO, ww, 0666);
    const std::string open_dir = dir_ + "/open";
    mkdir(open_dir.c_str(), 0777);
    chmod(open_dir.c_str(), 0777);  // not sticky
    copy_file(PROBE_SO, open_dir + "/probe.so", 0755);
    const std::string sticky = dir_ + "/sticky";
    mkdir(sticky.c_str(), 0777);
    chmod(sticky.c_str(), 01777);  // like /tmp
    mkdir((sticky + "/mine").c_str(), 0755);
    copy_file(PROBE_SO, sticky + "/mine/probe.so", 0755);
    const std::string allowed = dir_ + "/allowed";
    mkdir(allowed.c_str(), 0755);
    copy_file(PROBE_SO, allowed + "/probe.so", 0755);
    symlink(PROBE_SO, (allowed + "/link.so").c_str());  // leads out of it
    const std::string owner = "(owner " + my_name();
    std::vector<Case> cases = {
        {PROBE_SO, {}, {}},  // the build directory: loads
        {sticky + "/mine/probe.so", {}, {}},
        {ww, {}, {ww + " " + owner + ", mode 0666) can be changed by others: refused", "fix: chmod go-w"}},
        {open_dir + "/probe.so", {}, {"directory " + open_dir + " " + owner + ", mode 0777) can be written by others "
                                      "and is not sticky", "refused; fix"}},
        {PROBE_SO, {"--programs", allowed}, {"is not under a program directory given at start (" + allowed + ")"}},
        {allowed + "/link.so", {"--programs", allowed}, {"is not under a program directory given at start"}},
        {allowed + "/probe.so", {"--programs", allowed}, {}},
    };
    // umask 002 with a personal group (Debian, Fedora): group write by it is fine.
    const group* mine = getgrgid(getegid());
    if (mine && my_name() == mine->gr_name && (!mine->gr_mem || !mine->gr_mem[0])) {
        const std::string umask002 = dir_ + "/umask002";
        mkdir(umask002.c_str(), 0775);
        chmod(umask002.c_str(), 0775);
        copy_file(PROBE_SO, umask002 + "/probe.so", 0775);
        cases.push_back({umask002 + "/probe.so", {}, {}});
    }
    if (geteuid() == 0) {
        const std::string theirs = dir_ + "/theirs.so";
        copy_file(PROBE_SO, theirs, 0755);
        chown(theirs.c_str(), kNobody, kNobody);
        cases.push_back({theirs, {}, {theirs + " (owner nobody, mode 0755) belongs to another user: refused"}});
        // Group-writable by a group that is not the owner's personal one.
        const std::string shared = dir_ + "/shared";
        mkdir(shared.c_str(), 0770);
        chmod(shared.c_str(), 0770);
        chown(shared.c_str(), 0, kNobody);
        copy_file(PROBE_SO, shared + "/probe.so", 0755);
        cases.push_back({shared + "/probe.so", {}, {"directory " + shared + " (owner root, mode 0770) can be written by "
                                                    "others and is not sticky"}});
    } else {
        std::printf("(not root: the program of another owner is not tried; chown needs root)\n");
    }
    for (const Case& c : cases) {
        std::vector<std::string> args = {CHIMERA_RTPU_BIN, "--backplane", bp_, "--rtpu", "1"};
        args.insert(args.end(), c.extra.begin(), c.extra.end());
        args.insert(args.end(), {c.program, probe_out});
        unlink(probe_out.c_str());
        if (c.says.empty()) {
            const pid_t p = spawn(args, out_of(1), err_of(1));
            EXPECT_TRUE(wait_text(probe_out, "main")) << c.program << ": " << read_file(err_of(1));
            kill(p, SIGTERM);
            EXPECT_EQ(reap(p), 0) << c.program;
            continue;
        }
        const Outcome r = run(args);
        EXPECT_EQ(r.status, 1) << c.program << ": " << r.err;
        for (const std::string& w : c.says) EXPECT_TRUE(contains(r.err, w)) << c.program << ": " << r.err;
        EXPECT_EQ(count_lines(r.err), 1) << r.err;
        EXPECT_FALSE(exists(probe_out)) << c.program << " ran";
    }
}

TEST_F(SecurityTest, AnUntrustedSpawnRequestIsRefusedAndLoggedWithTheSlot) {
    create();
    const std::string allowed = dir_ + "/allowed";
    mkdir(allowed.c_str(), 0755);
    copy_file(PROBE_SO, allowed + "/probe.so", 0755);
    const pid_t p = start_rtpu(1, {"--programs", allowed});
    ASSERT_TRUE(wait_serving(1, p)) << read_file(err_of(1));
    const std::string probe_out = dir_ + "/probe.txt";
    const char* argv[] = {"probe", probe_out.c_str()};
    // Outside --programs (the build directory would load without it).
    EXPECT_EQ(chm_rtpu_spawn(1, PROBE_SO, 2, argv, nullptr), -EACCES);
    EXPECT_TRUE(contains(chm_rtpu_last_error(), "not under a program directory")) << chm_rtpu_last_error();
    // A link inside it that leads out of it.
    symlink(PROBE_SO, (allowed + "/link.so").c_str());
    EXPECT_EQ(chm_rtpu_spawn(1, (allowed + "/link.so").c_str(), 2, argv, nullptr), -EACCES);
    const std::string slot = std::to_string(chm_bp_self());
    EXPECT_TRUE(wait_text(err_of(1), "refused a spawn request from slot " + slot + ": " + PROBE_SO))
        << read_file(err_of(1));
    EXPECT_FALSE(exists(probe_out));
    // Nothing running was disturbed; the allowed one loads.
    EXPECT_EQ(chm_rtpu_ping(1, nullptr), 0);
    ASSERT_EQ(chm_rtpu_spawn(1, (allowed + "/probe.so").c_str(), 2, argv, nullptr), 0) << chm_rtpu_last_error();
    EXPECT_TRUE(wait_text(probe_out, "main"));
}

TEST_F(SecurityTest, RmRemovesOnlyLogsOfItsOwnUser) {
    if (geteuid() != 0) GTEST_SKIP() << "needs root to give a log to nobody (chown)";
    make_backplane(bp_);
    const std::string ours = bp_ + ".rtpu1.log", theirs = bp_ + ".rtpu7.log";
    { std::ofstream(ours) << "ours\n"; }
    { std::ofstream(theirs) << "theirs\n"; }
    ASSERT_EQ(chown(theirs.c_str(), kNobody, kNobody), 0);
    const Outcome r = chimera({"rm"});
    EXPECT_EQ(r.status, 0) << r.err;
    EXPECT_FALSE(exists(bp_));
    EXPECT_FALSE(exists(ours));
    EXPECT_TRUE(exists(theirs)) << "chimera rm removed another user's file";
}

// A member of the group a file was made for may attach it though another
// user owns it; the same user outside the group is refused.
TEST_F(SecurityTest, AMemberOfTheGroupMayAttachAFileMadeForIt) {
    if (geteuid() != 0) GTEST_SKIP() << "needs root to act as another user (setuid)";
    const gid_t lab = kNobody;  // nogroup: a group root's files do not normally have
    const std::string dir = dir_ + "/lab", bp = dir + "/lab.bp";
    ASSERT_EQ(chmod(dir_.c_str(), 0711), 0);
    ASSERT_EQ(mkdir(dir.c_str(), 0750), 0);
    ASSERT_EQ(chown(dir.c_str(), 0, lab), 0);
    make_backplane(bp, int(lab));
    // As nobody, in the group or not: what chm_bp_check_file says (its
    // error number as the exit status, its message through a pipe).
    auto as_nobody = [&](const std::string& path, bool member, std::string* said) {
        int pipefd[2];
        if (pipe(pipefd) != 0) return -1000;
        const pid_t p = fork();
        if (p == 0) {
            close(pipefd[0]);
            const gid_t groups[] = {lab};
            if (setgroups(member ? 1 : 0, groups) != 0 || setgid(member ? lab : kNobody - 1) != 0 ||
                setuid(kNobody) != 0)
                _exit(100);
            const int r = chm_bp_check_file(path.c_str());
            (void)!write(pipefd[1], chm_bp_last_error(), std::strlen(chm_bp_last_error()));
            _exit(r == 0 ? 0 : -r);
        }
        close(pipefd[1]);
        char buf[1024];
        const ssize_t k = read(pipefd[0], buf, sizeof buf - 1);
        close(pipefd[0]);
        *said = k > 0 ? std::string(buf, std::size_t(k)) : "";
        int st = 0;
        waitpid(p, &st, 0);
        return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
    };
    std::string said;
    EXPECT_EQ(as_nobody(bp, true, &said), 0) << said;
    // Outside the group the kernel already refuses to open a 0660 file.
    EXPECT_EQ(as_nobody(bp, false, &said), EACCES) << said;
    // Made group-writable by hand (no record in the header): refused to members.
    const std::string hand = dir + "/hand.bp";
    make_backplane(hand);
    ASSERT_EQ(chown(hand.c_str(), 0, lab), 0);
    ASSERT_EQ(chmod(hand.c_str(), 0660), 0);
    EXPECT_EQ(as_nobody(hand, true, &said), EPERM) << said;
    EXPECT_TRUE(contains(said, "not created for that group")) << said;
}
