// A private directory under /dev/shm for one multi-process test (its
// backplane file, logs, probes): made by SetUp, removed with everything
// under it by TearDown, also when the test failed. Shared by suites ipc
// and rtpu, by the bench's backplane rows (bench/ipc/rtpu.hpp:
// BackplaneFile) and by the host server's fuzz harness (its root).
#pragma once

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include <dirent.h>
#include <ftw.h>
#include <sys/stat.h>
#include <unistd.h>

namespace chm::test {

// Make /dev/shm/<prefix>XXXXXX; its path, or "" when mkdtemp failed (errno).
inline std::string make_private_dir(const char* prefix) {
    std::string tmpl = std::string("/dev/shm/") + prefix + "XXXXXX";
    return mkdtemp(tmpl.data()) ? tmpl : std::string();
}

// The names in `dir` (not . and ..).
inline std::vector<std::string> private_dir_entries(const std::string& dir) {
    std::vector<std::string> out;
    if (DIR* d = opendir(dir.c_str())) {
        while (dirent* e = readdir(d))
            if (std::strcmp(e->d_name, ".") && std::strcmp(e->d_name, "..")) out.push_back(e->d_name);
        closedir(d);
    }
    return out;
}

// `path` and everything under it, depth first. Symbolic links are
// removed, never followed (FTW_PHYS): a test's link to a file outside
// the directory leaves that file alone. A directory made unreadable
// (mode 000: a fuzzed host server may do that) is opened up and emptied.
inline int remove_tree_entry(const char* path, const struct stat*, int flag, FTW*);
inline void remove_tree(const char* path) { (void)nftw(path, remove_tree_entry, 16, FTW_DEPTH | FTW_PHYS); }
inline int remove_tree_entry(const char* path, const struct stat*, int flag, FTW*) {
    if (flag == FTW_DNR && chmod(path, 0700) == 0) remove_tree(path);
    std::remove(path);
    return 0;
}

// Remove a directory make_private_dir (or mkdtemp) made, with everything
// under it. Only a name of that form ("<prefix>-XXXXXX") is touched, so
// a wrong path (empty, "/", a parent) removes nothing.
inline void remove_private_dir(const std::string& dir) {
    const std::size_t slash = dir.find_last_of('/');
    if (slash == std::string::npos || dir.size() < slash + 8 || dir[dir.size() - 7] != '-') return;
    remove_tree(dir.c_str());
}

}  // namespace chm::test
