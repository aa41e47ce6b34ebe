// Who may attach a backplane, and where the default one lives. A process
// with write access to the file can disturb every RTPU on it and send them
// requests, so the file is treated like ssh's authorized_keys: reached
// without a final symlink, a regular file, owned by the caller, with no
// permission for others and group write only when it was made for a named
// group. The default path lies in a per-user directory that nobody else can
// create first (a fixed name in world-writable /dev/shm could be squatted).
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include <fcntl.h>
#include <grp.h>
#include <pwd.h>
#include <sys/stat.h>
#include <unistd.h>

#include "chimera/bp.h"
#include "ipc/backplane/backplane.hpp"

namespace chm::bp {

namespace {

// "nobody (uid 65534)"
void user_name(uid_t uid, char* buf, std::size_t n) {
    const passwd* pw = ::getpwuid(uid);
    if (pw && pw->pw_name) std::snprintf(buf, n, "%s (uid %u)", pw->pw_name, unsigned(uid));
    else std::snprintf(buf, n, "uid %u", unsigned(uid));
}

void group_name(gid_t gid, char* buf, std::size_t n) {
    const group* gr = ::getgrgid(gid);
    if (gr && gr->gr_name) std::snprintf(buf, n, "%s (gid %u)", gr->gr_name, unsigned(gid));
    else std::snprintf(buf, n, "gid %u", unsigned(gid));
}

const char* kind_of(mode_t m) {
    if (S_ISDIR(m)) return "a directory";
    if (S_ISFIFO(m)) return "a FIFO";
    if (S_ISCHR(m)) return "a character device";
    if (S_ISBLK(m)) return "a block device";
    if (S_ISSOCK(m)) return "a socket";
    if (S_ISLNK(m)) return "a symbolic link";
    if (S_ISREG(m)) return "a regular file";
    return "not a regular file";
}

bool in_group(gid_t gid) {
    if (::getegid() == gid) return true;
    gid_t groups[256];
    const int n = ::getgroups(256, groups);
    for (int i = 0; i < n; ++i)
        if (groups[i] == gid) return true;
    return false;
}

// The directory part of `path` ("." for a bare name).
void dir_of(const char* path, char* buf, std::size_t n) {
    const char* slash = std::strrchr(path, '/');
    if (!slash) std::snprintf(buf, n, ".");
    else if (slash == path) std::snprintf(buf, n, "/");
    else std::snprintf(buf, n, "%.*s", int(slash - path), path);
}

}  // namespace

int describe_untrusted_path(const char* path, char* why, std::size_t n) {
    struct stat ls{};
    if (::lstat(path, &ls) != 0 || S_ISREG(ls.st_mode)) return 0;  // open() reports it / fstat decides
    char owner[96];
    user_name(ls.st_uid, owner, sizeof owner);
    if (S_ISLNK(ls.st_mode)) {
        char target[512] = "?";
        const ssize_t k = ::readlink(path, target, sizeof target - 1);
        if (k >= 0) target[k] = 0;
        std::snprintf(why, n, "is a symbolic link (to %s, owner %s): refused, a backplane is never reached "
                      "through a link that someone may change; fix: name the real file after checking who owns it",
                      target, owner);
        return -ELOOP;
    }
    if (!S_ISREG(ls.st_mode)) {
        std::snprintf(why, n, "is %s (owner %s, mode 0%o), not a regular file: refused; fix: remove it "
                      "(after checking who made it) and let chimera start create the backplane",
                      kind_of(ls.st_mode), owner, unsigned(ls.st_mode & 07777));
        return -EBADMSG;
    }
    return 0;
}

int check_trust(const struct stat& st, const Header* h, char* why, std::size_t n) {
    const uid_t me = ::geteuid();
    const unsigned mode = unsigned(st.st_mode & 07777);
    // Made for a group: the creator recorded it, and mode and group still say so.
    const bool for_group = h && h->ext[kExtGroupFlag] == kGroupMarker && h->ext[kExtGroupId] == st.st_gid;
    const bool shared = for_group && (mode & 0777) == 0660;
    if (S_ISREG(st.st_mode) && !(mode & 0007) && (!(mode & 0020) || shared) &&
        (st.st_uid == me || (shared && in_group(st.st_gid))))
        return 0;  // the common case: no name lookups (NSS) on the way in
    char owner[96], self[96], grp[96];
    user_name(st.st_uid, owner, sizeof owner);
    user_name(me, self, sizeof self);
    group_name(st.st_gid, grp, sizeof grp);
    if (!S_ISREG(st.st_mode)) {
        std::snprintf(why, n, "is %s (owner %s, mode 0%o), not a regular file: refused; fix: remove it "
                      "(after checking who made it) and let chimera start create the backplane",
                      kind_of(st.st_mode), owner, mode);
        return -EBADMSG;
    }
    if (mode & 0007) {
        std::snprintf(why, n, "owner %s, mode 0%o: others have access (anyone could %s it): refused; "
                      "fix: chmod o-rwx on it (or remove it and let chimera start create it)", owner, mode,
                      (mode & 0002) ? "change" : "read");
        return -EPERM;
    }
    if ((mode & 0020) && !shared) {
        std::snprintf(why, n, "owner %s, group %s, mode 0%o: group-writable, but it was not created for that "
                      "group: refused; fix: chmod g-w on it, or create it for the group "
                      "(chimera start --group NAME: mode 0660)", owner, grp, mode);
        return -EPERM;
    }
    if (st.st_uid == me) return 0;  // root attaches root's files, as anyone their own
    if (shared && in_group(st.st_gid)) return 0;
    std::snprintf(why, n, "owner %s, group %s, mode 0%o: not yours (you are %s)%s: refused, its owner could "
                  "change it under your processes; fix: if it is yours, chown it to you; otherwise remove it "
                  "and create your own (chimera start)", owner, grp, mode, self,
                  shared ? " and you are not in its group" : "");
    return -EPERM;
}

int check_default_dir_of(const char* path, bool create) {
    char dir[4096], def[4096];
    dir_of(path, dir, sizeof dir);
    if (chm_bp_default_dir(def, sizeof def) != 0) return 0;
    if (std::strcmp(dir, def) != 0) return 0;
    return chm_bp_check_dir(def, create ? 1 : 0);
}

}  // namespace chm::bp

using namespace chm::bp;

extern "C" {

int chm_bp_default_dir(char* buf, size_t len) {
    if (!buf) return -EINVAL;
    int k;
    const char* xdg = std::getenv("XDG_RUNTIME_DIR");
    struct stat st{};
    // $XDG_RUNTIME_DIR only when it is a real directory of this user: under
    // sudo it may still name the invoking user's.
    if (xdg && xdg[0] == '/' && ::lstat(xdg, &st) == 0 && S_ISDIR(st.st_mode) && st.st_uid == ::geteuid())
        k = std::snprintf(buf, len, "%s/chimera", xdg);
    else
        k = std::snprintf(buf, len, "/dev/shm/chimera-%u", unsigned(::geteuid()));
    return (k < 0 || size_t(k) >= len) ? -ENAMETOOLONG : 0;
}

int chm_bp_default_path(char* buf, size_t len) {
    if (!buf) return -EINVAL;
    const char* env = std::getenv(CHM_BP_ENV);
    if (env && *env) {
        const int k = std::snprintf(buf, len, "%s", env);
        return (k < 0 || size_t(k) >= len) ? -ENAMETOOLONG : 0;
    }
    char dir[4096];
    if (int r = chm_bp_default_dir(dir, sizeof dir)) return r;
    const int k = std::snprintf(buf, len, "%s/backplane.bp", dir);
    return (k < 0 || size_t(k) >= len) ? -ENAMETOOLONG : 0;
}

}  // extern "C"

namespace chm::bp {

int path_or_default(const char** path, char* buf, std::size_t n) {
    if (*path) return 0;
    if (const int r = chm_bp_default_path(buf, n)) return set_error("default backplane path too long"), r;
    *path = buf;
    return 0;
}

}  // namespace chm::bp

extern "C" {

int chm_bp_check_dir(const char* dir, int create) {
    if (!dir || !*dir) return set_error("backplane directory: empty path"), -EINVAL;
    if (create && ::mkdir(dir, 0700) != 0 && errno != EEXIST) {
        const int e = errno;
        set_error("backplane directory %s: cannot create: %s", dir, std::strerror(e));
        return -e;
    }
    struct stat st{};
    if (::lstat(dir, &st) != 0) {
        const int e = errno;
        set_error("backplane directory %s: %s", dir, std::strerror(e));
        return -e;
    }
    const unsigned mode = unsigned(st.st_mode & 07777);
    if (S_ISDIR(st.st_mode) && st.st_uid == ::geteuid() && !(mode & 0077)) return 0;
    char owner[96], self[96];
    user_name(st.st_uid, owner, sizeof owner);
    user_name(::geteuid(), self, sizeof self);
    if (S_ISLNK(st.st_mode)) {
        set_error("backplane directory %s: is a symbolic link (owner %s): refused, someone may have made it "
                  "to take your backplane; fix: remove it after checking who made it (rm %s)", dir, owner, dir);
        return -ELOOP;
    }
    if (!S_ISDIR(st.st_mode)) {
        set_error("backplane directory %s: is %s (owner %s, mode 0%o): refused; fix: remove it after "
                  "checking who made it", dir, kind_of(st.st_mode), owner, mode);
        return -ENOTDIR;
    }
    if (st.st_uid != ::geteuid()) {
        set_error("backplane directory %s: owner %s, mode 0%o: not yours (you are %s): refused, someone else "
                  "created it first; fix: remove it after checking who made it (rm -r %s)", dir, owner, mode,
                  self, dir);
        return -EPERM;
    }
    if (mode & 0077) {
        set_error("backplane directory %s: owner %s, mode 0%o: others have access: refused; fix: chmod 0700 %s",
                  dir, owner, mode, dir);
        return -EPERM;
    }
    return 0;
}

int chm_bp_check_file(const char* path) {
    char defpath[4096];
    if (int r = path_or_default(&path, defpath, sizeof defpath)) return r;
    View v;
    int fd = -1;
    char why[640];
    if (int r = map_file(path, false, &v, &fd, why, sizeof why, true)) {
        set_error("backplane %s: %s", path, why);
        return r;
    }
    unmap(&v);
    ::close(fd);
    return 0;
}

}  // extern "C"
