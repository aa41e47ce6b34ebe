// Whether a shared object about to be loaded names libchimera among the
// libraries it needs (DT_NEEDED). A control program or module must not:
// the RTPU process carries libchimera and exports it, and a second copy
// loaded beside it would be a second kernel, heap and backplane attachment
// whose state nobody initialised (or, when the dynamic linker cannot find
// it, a refusal that names libchimera and not the program). Read with
// pread only: the file is not trusted to be well formed, so every offset
// is checked against the file before it is used; a file that is not an ELF
// object of this machine's class is left to dlopen to refuse.
#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstring>

#include <fcntl.h>
#include <link.h>
#include <sys/stat.h>
#include <unistd.h>

#include "prog/trust.hpp"

namespace chm::kernel {
namespace {

using Ehdr = ElfW(Ehdr);
using Phdr = ElfW(Phdr);
using Dyn = ElfW(Dyn);

constexpr unsigned kMaxPhdrs = 64;
constexpr unsigned kMaxDyn = 4096;

bool read_at(int fd, void* buf, std::size_t n, std::uint64_t off, std::uint64_t file_size) {
    if (off > file_size || n > file_size - off) return false;
    return ::pread(fd, buf, n, off_t(off)) == ssize_t(n);
}

// The file offset of virtual address `va` inside one of the PT_LOAD
// segments, or false.
bool va_to_offset(const Phdr* ph, unsigned n, std::uint64_t va, std::uint64_t* off) {
    for (unsigned i = 0; i < n; ++i)
        if (ph[i].p_type == PT_LOAD && va >= ph[i].p_vaddr && va - ph[i].p_vaddr < ph[i].p_filesz) {
            *off = ph[i].p_offset + (va - ph[i].p_vaddr);
            return true;
        }
    return false;
}

}  // namespace

int program_needs_libchimera(const char* real, char* why, std::size_t n) {
    const int fd = ::open(real, O_RDONLY | O_CLOEXEC);
    if (fd < 0) return 0;  // dlopen will say why
    struct stat st{};
    Ehdr eh{};
    Phdr ph[kMaxPhdrs];
    int found = 0;
    char lib[128] = "";
    do {
        if (::fstat(fd, &st) != 0 || !read_at(fd, &eh, sizeof eh, 0, std::uint64_t(st.st_size))) break;
        if (std::memcmp(eh.e_ident, ELFMAG, SELFMAG) != 0 || eh.e_ident[EI_CLASS] != (sizeof(void*) == 8 ? ELFCLASS64 : ELFCLASS32) ||
            eh.e_phentsize != sizeof(Phdr) || eh.e_phnum == 0 || eh.e_phnum > kMaxPhdrs)
            break;
        const std::uint64_t size = std::uint64_t(st.st_size);
        if (!read_at(fd, ph, sizeof(Phdr) * eh.e_phnum, eh.e_phoff, size)) break;
        const Phdr* dyn = nullptr;
        for (unsigned i = 0; i < eh.e_phnum; ++i)
            if (ph[i].p_type == PT_DYNAMIC) dyn = &ph[i];
        if (!dyn) break;
        // The dynamic section, read in chunks (no large buffer: this may
        // run on a task's stack): the string table first, then the names.
        const std::uint64_t count = std::min<std::uint64_t>(dyn->p_filesz / sizeof(Dyn), kMaxDyn);
        Dyn d[32];
        auto each = [&](auto&& fn) {
            for (std::uint64_t at = 0; at < count; at += 32) {
                const std::size_t k = std::size_t(std::min<std::uint64_t>(32, count - at));
                if (!read_at(fd, d, sizeof(Dyn) * k, dyn->p_offset + at * sizeof(Dyn), size)) return;
                for (std::size_t i = 0; i < k; ++i)
                    if (d[i].d_tag == DT_NULL || !fn(d[i])) return;
            }
        };
        std::uint64_t strtab = 0, strsz = 0;
        bool have_strtab = false;
        each([&](const Dyn& e) {
            if (e.d_tag == DT_STRTAB) have_strtab = true, strtab = e.d_un.d_ptr;
            if (e.d_tag == DT_STRSZ) strsz = e.d_un.d_val;
            return true;
        });
        std::uint64_t stroff = 0;
        if (!have_strtab || !va_to_offset(ph, eh.e_phnum, strtab, &stroff)) break;
        each([&](const Dyn& e) {
            if (e.d_tag != DT_NEEDED || e.d_un.d_val >= strsz) return true;
            char name[sizeof lib] = {};
            const std::uint64_t at = stroff + e.d_un.d_val;
            const std::size_t k = std::size_t(std::min<std::uint64_t>(sizeof name - 1, size > at ? size - at : 0));
            if (k == 0 || !read_at(fd, name, k, at, size)) return true;
            name[k] = 0;
            if (std::strncmp(name, "libchimera.so", 13) != 0) return true;
            std::snprintf(lib, sizeof lib, "%s", name);
            found = 1;
            return false;
        });
    } while (false);
    ::close(fd);
    if (!found) return 0;
    std::snprintf(why, n,
                  "%s: linked against %s: a control program or module must not link libchimera (the RTPU "
                  "provides every chm_* call); build it with the headers only: cc -shared -fPIC prog.c "
                  "$(pkg-config --cflags chimera) -o prog.so (no --libs)",
                  real, lib);
    return -ENOEXEC;
}

}  // namespace chm::kernel
