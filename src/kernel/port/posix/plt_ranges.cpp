// The PLT entries of a loaded object, carved out of the preemptible
// ranges. Where the compiler cannot call a shared library through its GOT
// (-fno-plt is honoured on x86-64 and aarch64, not on m68k), the
// allocator's calls to memset, memcpy, errno and syscall go through PLT entries
// in the executable's own text, which is preemptible. A task preempted on
// such an entry inside a malloc that the C library made with a FILE's lock
// held leaves that lock to the next task on the thread (glibc's locks are
// recursive per OS thread): seen as lost stdio lines under a 50 us quantum
// on m68k. A PLT entry does no work of its own, so deferring a preemption that
// lands there costs nothing but the retry.
//
// The entries are found from the object's section headers (.plt, .plt.sec,
// .plt.got, .iplt), read from its file once at kernel start; program
// headers alone do not tell the entries from the code around them.
#include "port.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <elf.h>
#include <fcntl.h>
#include <link.h>
#include <unistd.h>

namespace chm::port {

namespace {

struct Found {
    std::uintptr_t want;
    std::uintptr_t base = 0;
    const char* file = nullptr;
};

int find_object(dl_phdr_info* info, std::size_t, void* arg) {
    auto* f = static_cast<Found*>(arg);
    for (int i = 0; i < info->dlpi_phnum; ++i) {
        const auto& ph = info->dlpi_phdr[i];
        const std::uintptr_t lo = info->dlpi_addr + ph.p_vaddr;
        if (ph.p_type == PT_LOAD && f->want >= lo && f->want < lo + ph.p_memsz) {
            f->base = info->dlpi_addr;
            // The main program has no name here.
            f->file = info->dlpi_name && *info->dlpi_name ? info->dlpi_name : "/proc/self/exe";
            return 1;
        }
    }
    return 0;
}

bool read_at(int fd, void* to, std::size_t n, off_t at) {
    return ::pread(fd, to, n, at) == static_cast<ssize_t>(n);
}

bool is_plt_section(const char* name) {
    return std::strcmp(name, ".plt") == 0 || std::strcmp(name, ".plt.sec") == 0 ||
           std::strcmp(name, ".plt.got") == 0 || std::strcmp(name, ".iplt") == 0;
}

}  // namespace

int preemptible_exclude_plt(const void* addr) {
    Found f{reinterpret_cast<std::uintptr_t>(addr)};
    dl_iterate_phdr(find_object, &f);
    if (!f.file) return -ENOENT;
    const int fd = ::open(f.file, O_RDONLY | O_CLOEXEC);
    if (fd < 0) return -errno;
    int carved = 0;
    ElfW(Ehdr) eh;
    // A file that does not look like the object loaded from it (replaced
    // since, or an unexpected layout) is left alone: -ENOEXEC.
    int r = -ENOEXEC;
    if (read_at(fd, &eh, sizeof eh, 0) && std::memcmp(eh.e_ident, ELFMAG, SELFMAG) == 0 &&
        eh.e_ident[EI_CLASS] == (sizeof(void*) == 8 ? ELFCLASS64 : ELFCLASS32) &&
        eh.e_shentsize == sizeof(ElfW(Shdr)) && eh.e_shnum > 0 && eh.e_shnum <= 1024 &&
        eh.e_shstrndx < eh.e_shnum) {
        ElfW(Shdr) names;
        char buf[16];
        if (read_at(fd, &names, sizeof names, off_t(eh.e_shoff + eh.e_shstrndx * sizeof(ElfW(Shdr))))) {
            r = 0;
            for (unsigned i = 0; i < eh.e_shnum; ++i) {
                ElfW(Shdr) sh;
                if (!read_at(fd, &sh, sizeof sh, off_t(eh.e_shoff + i * sizeof sh))) break;
                if (!(sh.sh_flags & SHF_EXECINSTR) || sh.sh_size == 0 || sh.sh_name >= names.sh_size) continue;
                const std::size_t n = std::min<std::size_t>(sizeof buf - 1, names.sh_size - sh.sh_name);
                const ssize_t got = ::pread(fd, buf, n, off_t(names.sh_offset + sh.sh_name));
                if (got <= 0) continue;
                buf[got] = '\0';
                if (!is_plt_section(buf)) continue;
                const std::uintptr_t lo = f.base + sh.sh_addr;
                preemptible_range_exclude(lo, lo + sh.sh_size);
                ++carved;
            }
        }
    }
    ::close(fd);
    return r < 0 ? r : carved;
}

}  // namespace chm::port
