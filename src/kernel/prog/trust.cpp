// Which files an RTPU may load as programs. A load request can come from
// any process that may write the backplane (express mail), and dlopen runs
// the file's code with the RTPU's privileges, so the file must be one that
// nobody but the RTPU's user (or root) could have changed: sudo's rule for
// its plug-ins. Or, when directories were given at start (chimera-rtpu
// --programs DIR), it must lie under one of them, and only there.
#include <cerrno>
#include <climits>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include <grp.h>
#include <pwd.h>
#include <sys/stat.h>
#include <unistd.h>

#include "chimera/program.h"
#include "prog/trust.hpp"

namespace chm::kernel {
namespace {

constexpr int kMaxDirs = 8;
char g_dirs[kMaxDirs][PATH_MAX];
int g_ndirs = 0;

void owner_name(uid_t uid, char* buf, std::size_t n) {
    const passwd* pw = ::getpwuid(uid);
    if (pw && pw->pw_name) std::snprintf(buf, n, "%s", pw->pw_name);
    else std::snprintf(buf, n, "uid %u", unsigned(uid));
}

bool trusted_owner(uid_t uid) { return uid == ::geteuid() || uid == 0; }

// Group write counts as "others" unless the group is the owner's personal
// one (same name, primary group, no other members): with such groups
// (Debian's and Fedora's default) users run with umask 002, and refusing
// their builds would make the rule something people switch off.
bool personal_group(gid_t gid, uid_t owner) {
    const passwd* pw = ::getpwuid(owner);
    if (!pw || pw->pw_gid != gid || !pw->pw_name) return false;
    char name[256];
    std::snprintf(name, sizeof name, "%s", pw->pw_name);  // getgrgid may reuse static storage
    const group* gr = ::getgrgid(gid);
    return gr && gr->gr_name && std::strcmp(gr->gr_name, name) == 0 && (!gr->gr_mem || !gr->gr_mem[0]);
}

bool writable_by_others(const struct stat& st) {
    return (st.st_mode & 0002) || ((st.st_mode & 0020) && !personal_group(st.st_gid, st.st_uid));
}

// Under one of the --programs directories (both resolved: no link can
// lead out of them).
bool under_given_dir(const char* real) {
    for (int i = 0; i < g_ndirs; ++i) {
        const std::size_t k = std::strlen(g_dirs[i]);
        if (std::strncmp(real, g_dirs[i], k) == 0 && (real[k] == '/' || (k == 1 && g_dirs[i][0] == '/')))
            return true;
    }
    return false;
}

}  // namespace

int program_path_check(const char* path, char* real, std::size_t rlen, char* why, std::size_t n) {
    char buf[PATH_MAX];
    if (!::realpath(path, buf)) {
        const int e = errno;
        std::snprintf(why, n, "%s: %s", path, std::strerror(e));
        return e == ENOENT ? -ENOENT : -e;
    }
    if (std::strlen(buf) >= rlen) {
        std::snprintf(why, n, "%s: path too long", path);
        return -ENAMETOOLONG;
    }
    std::strcpy(real, buf);
    struct stat st{};
    if (::stat(real, &st) != 0) {
        const int e = errno;
        std::snprintf(why, n, "%s: %s", real, std::strerror(e));
        return -e;
    }
    char owner[64] = "";  // named only in a refusal (a lookup may read /etc/passwd)
    if (!S_ISREG(st.st_mode) || !trusted_owner(st.st_uid) || writable_by_others(st))
        owner_name(st.st_uid, owner, sizeof owner);
    if (!S_ISREG(st.st_mode)) {
        std::snprintf(why, n, "%s (owner %s, mode 0%o) is not a regular file: refused", real, owner,
                      unsigned(st.st_mode & 07777));
        return -EACCES;
    }
    if (g_ndirs > 0) {
        if (under_given_dir(real)) return 0;
        char list[512] = "";
        for (int i = 0; i < g_ndirs; ++i)
            std::snprintf(list + std::strlen(list), sizeof list - std::strlen(list), "%s%.200s", i ? ", " : "",
                          g_dirs[i]);
        std::snprintf(why, n, "%s is not under a program directory given at start (%s): refused; fix: put it "
                      "there, or start the RTPU with --programs naming its directory", real, list);
        return -EACCES;
    }
    if (!trusted_owner(st.st_uid) || writable_by_others(st)) {
        std::snprintf(why, n, "%s (owner %s, mode 0%o) %s: refused; fix: %s, or start the RTPU with "
                      "--programs DIR naming a directory you trust", real, owner, unsigned(st.st_mode & 07777),
                      trusted_owner(st.st_uid) ? "can be changed by others" : "belongs to another user",
                      trusted_owner(st.st_uid) ? "chmod go-w on it" : "copy it to a directory of yours");
        return -EACCES;
    }
    // Every directory above it: owned by us or root, and writable by no one
    // else, except a sticky one (/tmp) above an entry of ours or root's,
    // which others can neither rename nor delete.
    uid_t child_uid = st.st_uid;
    char dir[PATH_MAX];
    std::strcpy(dir, real);
    for (;;) {
        char* slash = std::strrchr(dir, '/');
        if (!slash) break;
        if (slash == dir) slash[1] = 0;
        else *slash = 0;
        struct stat ds{};
        if (::lstat(dir, &ds) != 0) {
            const int e = errno;
            std::snprintf(why, n, "%s: directory %s: %s", real, dir, std::strerror(e));
            return -e;
        }
        const unsigned mode = unsigned(ds.st_mode & 07777);
        const bool others = writable_by_others(ds);
        if (!trusted_owner(ds.st_uid) || others) owner_name(ds.st_uid, owner, sizeof owner);
        if (!trusted_owner(ds.st_uid)) {
            std::snprintf(why, n, "%s: directory %s (owner %s, mode 0%o) belongs to another user, who could "
                          "replace the program: refused; fix: move it to a directory of yours, or start the RTPU "
                          "with --programs DIR", real, dir, owner, mode);
            return -EACCES;
        }
        if (others && !((mode & S_ISVTX) && trusted_owner(child_uid))) {
            std::snprintf(why, n, "%s: directory %s (owner %s, mode 0%o) can be written by others%s, who could "
                          "replace the program: refused; fix: chmod go-w %s, or start the RTPU with --programs DIR",
                          real, dir, owner, mode, (mode & S_ISVTX) ? "" : " and is not sticky", dir);
            return -EACCES;
        }
        if (dir[1] == 0) break;  // "/" checked
        child_uid = ds.st_uid;
    }
    return 0;
}

}  // namespace chm::kernel

using namespace chm::kernel;

extern "C" {

int chm_program_trust_dir(const char* dir) {
    if (!dir) {
        g_ndirs = 0;
        return 0;
    }
    if (g_ndirs == kMaxDirs) return -ENOSPC;
    char real[PATH_MAX];
    if (!::realpath(dir, real)) return -errno;
    struct stat st{};
    if (::stat(real, &st) != 0) return -errno;
    if (!S_ISDIR(st.st_mode)) return -ENOTDIR;
    std::strcpy(g_dirs[g_ndirs++], real);
    return 0;
}

}  // extern "C"
