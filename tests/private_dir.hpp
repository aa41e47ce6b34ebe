// A private directory under /dev/shm for one multi-process test (its
// backplane file, logs, probes): made by SetUp, emptied and removed by
// TearDown, also when the test failed. Shared by suites ipc and rtpu and
// by the bench's backplane rows (bench/ipc/rtpu.hpp: BackplaneFile).
#pragma once

#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include <dirent.h>
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

// Remove every file in `dir`, then `dir` (tests make no subdirectories).
inline void remove_private_dir(const std::string& dir) {
    if (dir.empty()) return;
    for (const std::string& name : private_dir_entries(dir)) unlink((dir + "/" + name).c_str());
    rmdir(dir.c_str());
}

}  // namespace chm::test
