// Which files an RTPU may load as programs (trust.cpp, elf.cpp).
#pragma once

#include <cstddef>

namespace chm::kernel {

// Resolve `path` (every link followed) into `real` and check that it may be
// loaded: under a directory given to chm_program_trust_dir when any was;
// otherwise a regular file owned by this user or root, writable by no one
// else, in directories owned by this user or root that no one else can
// write (a sticky directory above an entry of ours or root's is fine).
// 0, or -ENOENT (no such file) / -EACCES (refused) / -errno with `why`.
int program_path_check(const char* path, char* real, std::size_t rlen, char* why, std::size_t n);

// elf.cpp: -ENOEXEC with `why` ("FILE: linked against LIB: ...", the fix)
// when the shared object `real` needs libchimera (DT_NEEDED): the RTPU
// already carries it. 0 otherwise, also for a file that is no ELF object
// of this machine's class (dlopen refuses those in its own words).
int program_needs_libchimera(const char* real, char* why, std::size_t n);

}  // namespace chm::kernel
