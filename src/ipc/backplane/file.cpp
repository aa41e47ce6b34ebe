// The backplane file itself: planning the layout from a geometry, building
// a new file under a temporary name and publishing it atomically, and
// validating a file before any of it is trusted or mapped.
#include <cerrno>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>

#include <fcntl.h>
#include <pwd.h>
#include <stdio.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include "chimera/bp.h"
#include "ipc/backplane/backplane.hpp"
#include "kernel/err/last.hpp"

namespace chm::bp {

namespace {

thread_local char t_error[1024];

constexpr std::uint64_t round_up(std::uint64_t x, std::uint64_t a) { return (x + a - 1) / a * a; }

bool in_my_groups(gid_t gid) {
    if (::getegid() == gid || ::geteuid() == 0) return true;
    gid_t groups[256];
    const int k = ::getgroups(256, groups);
    for (int i = 0; i < k; ++i)
        if (groups[i] == gid) return true;
    return false;
}

}  // namespace

void set_error(const char* fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    std::vsnprintf(t_error, sizeof t_error, fmt, ap);
    va_end(ap);
    kernel::err_last_set(t_error);  // chm_err_last
}

bool plan_layout(const Geometry& g, Header* h, char* why, std::size_t n) {
    auto bad = [&](const char* field, std::uint64_t v, const char* rule) {
        std::snprintf(why, n, "%s = %llu: %s", field, static_cast<unsigned long long>(v), rule);
        return false;
    };
    if (g.rtpu_slots < kMinSlots || g.rtpu_slots > kMaxSlots)
        return bad("rtpu_slots", g.rtpu_slots, "must be 2..32");
    if (g.ring_records < 1 || g.ring_records > 4096)
        return bad("ring_records", g.ring_records, "must be 1..4096");
    if (g.ring_record_size < 16 || g.ring_record_size > 65536 || g.ring_record_size % 16)
        return bad("ring_record_size", g.ring_record_size, "must be a multiple of 16 in 16..65536");
    if (g.local_window_size < kPage || g.local_window_size % kPage)
        return bad("local_window_size", g.local_window_size, "must be a positive multiple of 4096");
    if (g.common_size < kPage || g.common_size % kPage)
        return bad("common_size", g.common_size, "must be a positive multiple of 4096");
    if (g.registry_capacity < 1 || g.registry_capacity > 65536)
        return bad("registry_capacity", g.registry_capacity, "must be 1..65536");

    const std::uint64_t stride = round_up(sizeof(RingHeader) + std::uint64_t(g.ring_records) * g.ring_record_size, kPage);
    const std::uint64_t sizes[kRegionCount] = {
        round_up(std::uint64_t(g.rtpu_slots) * sizeof(RtpuEntry), kPage),
        stride * g.rtpu_slots,
        round_up(std::uint64_t(g.registry_capacity) * sizeof(RegistryEntry), kPage),
        std::uint64_t(g.local_window_size) * g.rtpu_slots,
        g.common_size,
    };
    std::uint64_t at = kPage;  // the header's page
    for (unsigned r = 0; r < kRegionCount; ++r) {
        if (at + sizes[r] > kMaxFileSize)
            return bad("file size", at + sizes[r], "the layout must stay below 4 GiB");
        h->regions[r].offset = static_cast<std::uint32_t>(at);
        h->regions[r].size = static_cast<std::uint32_t>(sizes[r]);
        at += sizes[r];
    }
    h->magic = kMagic;
    h->version = kLayoutVersion;
    h->header_size = sizeof(Header);
    h->file_size = static_cast<std::uint32_t>(at);
    h->geo = g;
    h->table_entry_size = sizeof(RtpuEntry);
    h->registry_entry_size = sizeof(RegistryEntry);
    h->ring_stride = static_cast<std::uint32_t>(stride);
    return true;
}

int validate_header(const Header& h, std::uint64_t file_size, char* why, std::size_t n) {
    auto bad = [&](const char* fmt, auto... args) {
        std::snprintf(why, n, fmt, args...);
        return -EBADMSG;
    };
    if (file_size < sizeof(Header))
        return bad("file is %llu bytes, shorter than a header (truncated or not a backplane)",
                   static_cast<unsigned long long>(file_size));
    if (h.magic == kMagicSwapped) return bad("header.magic: written with the other byte order");
    if (h.magic != kMagic) return bad("header.magic is 0x%08x, expected 0x%08x (not a backplane)", h.magic, kMagic);
    if (h.version != kLayoutVersion)
        return bad("header.version is %u, this build reads layout version %u", h.version, kLayoutVersion);
    if (h.header_size != sizeof(Header))
        return bad("header.header_size is %u, expected %u", h.header_size, unsigned(sizeof(Header)));
    if (h.file_size != file_size)
        return bad("header.file_size is %u but the file has %llu bytes (truncated or extended)",
                   h.file_size, static_cast<unsigned long long>(file_size));
    if (h.table_entry_size != sizeof(RtpuEntry))
        return bad("header.table_entry_size is %u, expected %u", h.table_entry_size, unsigned(sizeof(RtpuEntry)));
    if (h.registry_entry_size != sizeof(RegistryEntry))
        return bad("header.registry_entry_size is %u, expected %u", h.registry_entry_size,
                   unsigned(sizeof(RegistryEntry)));
    // The geometry must be one a creator could have made, and the regions
    // must be exactly what it implies: then every table index is in range.
    Header plan{};
    char gwhy[160];
    if (!plan_layout(h.geo, &plan, gwhy, sizeof gwhy)) return bad("header.geo.%s", gwhy);
    for (unsigned r = 0; r < kRegionCount; ++r) {
        const Region& g = h.regions[r];
        const char* name = kRegionNames[r];
        if (std::uint64_t(g.offset) + g.size > file_size)
            return bad("header.regions[%s]: offset %u + size %u lies outside the file (%llu bytes)",
                       name, g.offset, g.size, static_cast<unsigned long long>(file_size));
        if (g.offset < kPage || g.offset % kPage)
            return bad("header.regions[%s].offset %u is not a page-aligned offset past the header", name, g.offset);
        for (unsigned o = 0; o < r; ++o) {
            const Region& p = h.regions[o];
            if (g.offset < p.offset + p.size && p.offset < g.offset + g.size)
                return bad("header.regions[%s] [%u, +%u) overlaps header.regions[%s] [%u, +%u)", name,
                           g.offset, g.size, kRegionNames[o], p.offset, p.size);
        }
        if (g.size != plan.regions[r].size)
            return bad("header.regions[%s].size is %u, the geometry implies %u", name, g.size, plan.regions[r].size);
    }
    if (h.ring_stride != plan.ring_stride)
        return bad("header.ring_stride is %u, the geometry implies %u", h.ring_stride, plan.ring_stride);
    if (h.file_size != plan.file_size)
        return bad("header.file_size is %u, the geometry implies %u", h.file_size, plan.file_size);
    return 0;
}

int map_file(const char* path, bool writable, View* out, int* fd_out, char* why, std::size_t n, bool trust) {
    if (trust) {
        // The directory first: a squatted default directory is the attack,
        // whatever file it holds.
        if (int r = check_default_dir_of(path, false); r && r != -ENOENT) {
            std::snprintf(why, n, "%s", chm_bp_last_error());
            return r;
        }
        if (int r = describe_untrusted_path(path, why, n)) return r;
    }
    // O_NOFOLLOW: a link swapped in after the check above is not followed;
    // O_NONBLOCK: a FIFO put there does not hang the opener.
    const int fd = ::open(path, (writable ? O_RDWR : O_RDONLY) | O_CLOEXEC | O_NOFOLLOW | O_NONBLOCK);
    if (fd < 0) {
        const int e = errno;
        if (e == ELOOP) std::snprintf(why, n, "is a symbolic link: refused; fix: name the real file");
        else std::snprintf(why, n, "cannot open: %s", std::strerror(e));
        return -e;
    }
    struct stat st{};
    Header h{};
    int r = 0;
    if (::fstat(fd, &st) != 0) {
        r = -errno;
        std::snprintf(why, n, "cannot stat: %s", std::strerror(-r));
    } else if (!S_ISREG(st.st_mode)) {
        r = trust ? check_trust(st, nullptr, why, n) : -EBADMSG;
        if (!trust) std::snprintf(why, n, "not a regular file");
    } else {
        const ssize_t got = st.st_size >= static_cast<off_t>(sizeof h) ? ::pread(fd, &h, sizeof h, 0) : 0;
        if (got < 0) {
            r = -errno;
            std::snprintf(why, n, "cannot read the header: %s", std::strerror(-r));
        } else if (trust && (r = check_trust(st, got == ssize_t(sizeof h) ? &h : nullptr, why, n)) != 0) {
            // refused before anything in it is used
        } else {
            r = validate_header(h, static_cast<std::uint64_t>(st.st_size), why, n);
        }
    }
    if (r == 0) {
        void* p = ::mmap(nullptr, h.file_size, writable ? PROT_READ | PROT_WRITE : PROT_READ, MAP_SHARED, fd, 0);
        if (p == MAP_FAILED) {
            r = -errno;
            std::snprintf(why, n, "cannot map %u bytes: %s", h.file_size, std::strerror(-r));
        } else {
            out->base = static_cast<char*>(p);
            out->size = h.file_size;
            out->layout = layout_of(h);  // the validated copy: lookups never reread the file's header
        }
    }
    if (r != 0) {
        ::close(fd);
        return r;
    }
    *fd_out = fd;
    return 0;
}

void unmap(View* v) {
    if (v->base) ::munmap(v->base, v->size);
    v->base = nullptr;
    v->size = 0;
}

namespace {

void init_contents(const View& v, const Header& plan) {
    Header* h = v.hdr();
    std::memcpy(static_cast<void*>(h), &plan, sizeof plan);  // fresh zeroed file; no live atomics yet
    h->magic = 0;  // written last
    timespec ts{};
    ::clock_gettime(CLOCK_REALTIME, &ts);
    h->created_ns = std::uint64_t(ts.tv_sec) * 1000000000ull + std::uint64_t(ts.tv_nsec);
    h->creator_pid = static_cast<std::uint32_t>(::getpid());
    for (std::uint32_t s = 0; s < plan.geo.rtpu_slots; ++s) {
        RingHeader* r = v.ring(s);
        r->capacity = plan.geo.ring_records;
        r->record_size = plan.geo.ring_record_size;
        arena_init(v, plan.regions[kRegionLocals].offset + s * plan.geo.local_window_size,
                   plan.geo.local_window_size);
    }
    arena_init(v, plan.regions[kRegionCommon].offset, plan.geo.common_size);
    std::atomic_thread_fence(std::memory_order_release);
    h->magic = kMagic;
}

// Publish `tmp` as `path` without ever replacing an existing file.
int publish(const char* tmp, const char* path) {
    if (::renameat2(AT_FDCWD, tmp, AT_FDCWD, path, RENAME_NOREPLACE) == 0) return 0;
    if (errno != EINVAL && errno != ENOSYS) return -errno;
    if (::link(tmp, path) != 0) return -errno;  // filesystems without RENAME_NOREPLACE
    ::unlink(tmp);
    return 0;
}

}  // namespace

}  // namespace chm::bp

using namespace chm::bp;

extern "C" {

void chm_bp_config_init(chm_bp_config_t* cfg) {
    if (!cfg) return;
    cfg->rtpu_slots = 32;
    cfg->ring_records = 64;
    cfg->ring_record_size = 1024;  // a servo request (module spawn, switch) needs up to ~900
    cfg->local_window_size = 256u << 10;
    cfg->common_size = 8u << 20;
    cfg->registry_capacity = 256;
    cfg->mode = 0600;
    cfg->group = -1;
}

int chm_bp_create(const char* path, const chm_bp_config_t* cfg) {
    char defpath[4096];
    if (int r = path_or_default(&path, defpath, sizeof defpath)) return r;
    chm_bp_config_t c;
    chm_bp_config_init(&c);
    if (cfg) c = *cfg;
    Geometry g{c.rtpu_slots, c.ring_records, c.ring_record_size, c.local_window_size,
               c.common_size, c.registry_capacity};
    Header plan{};
    char why[256];
    if (!plan_layout(g, &plan, why, sizeof why)) {
        set_error("backplane %s: config %s", path, why);
        return std::strstr(why, "4 GiB") ? -EFBIG : -EINVAL;
    }
    if (c.mode & ~0777u) return set_error("backplane %s: config mode 0%o has bits outside 0777", path, c.mode), -EINVAL;
    // A file that attach would refuse is never made (trust.cpp).
    if (c.group >= 0) c.mode = 0660;
    else if (c.mode & 0027)
        return set_error("backplane %s: config mode 0%o gives %s write access: attaching would be refused "
                         "(set config.group to share it with a group: mode 0660)", path, c.mode,
                         (c.mode & 0007) ? "others" : "the group"), -EINVAL;
    if (c.mode & 0007)
        return set_error("backplane %s: config mode 0%o gives others access: attaching would be refused", path,
                         c.mode), -EINVAL;
    if (c.group >= 0 && !in_my_groups(gid_t(c.group)))
        return set_error("backplane %s: config group %d: you are not a member of it", path, int(c.group)), -EPERM;
    if (int e = check_default_dir_of(path, true)) return e;

    // The temporary file lives in the same directory so the publish is a
    // rename within one file system.
    char tmp[4200];
    const char* slash = std::strrchr(path, '/');
    const int dlen = slash ? int(slash - path + 1) : 0;
    static std::atomic<unsigned> s_seq{0};
    const int tn = std::snprintf(tmp, sizeof tmp, "%.*s.%s.tmp-%d-%u", dlen, path, slash ? slash + 1 : path,
                                 int(::getpid()), s_seq.fetch_add(1));
    if (tn < 0 || size_t(tn) >= sizeof tmp) return set_error("backplane %s: path too long", path), -ENAMETOOLONG;

    struct stat st{};
    if (::lstat(path, &st) == 0) return set_error("backplane %s: already exists", path), -EEXIST;

    const int fd = ::open(tmp, O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC | O_NOFOLLOW, c.mode);
    if (fd < 0) {
        const int e = errno;
        set_error("backplane %s: cannot create %s: %s", path, tmp, std::strerror(e));
        return -e;
    }
    // The exact mode and group, whatever the umask.
    int r = 0;
    if ((c.group >= 0 && ::fchown(fd, uid_t(-1), gid_t(c.group)) != 0) || ::fchmod(fd, c.mode) != 0) {
        r = -errno;
        set_error("backplane %s: cannot set group %d and mode 0%o: %s", path, int(c.group), c.mode,
                  std::strerror(-r));
    } else if ((r = ::posix_fallocate(fd, 0, static_cast<off_t>(plan.file_size))) != 0) {
        set_error("backplane %s: cannot reserve %u bytes: %s", path, plan.file_size, std::strerror(r));
        r = -r;
    } else {
        void* p = ::mmap(nullptr, plan.file_size, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
        if (p == MAP_FAILED) {
            r = -errno;
            set_error("backplane %s: cannot map: %s", path, std::strerror(-r));
        } else {
            View v;
            v.base = static_cast<char*>(p);
            v.size = plan.file_size;
            if (c.group >= 0) {  // group members may attach (trust.cpp)
                plan.ext[kExtGroupFlag] = kGroupMarker;
                plan.ext[kExtGroupId] = std::uint32_t(c.group);
            }
            v.layout = layout_of(plan);
            init_contents(v, plan);
            unmap(&v);
            r = publish(tmp, path);
            if (r) set_error("backplane %s: cannot publish: %s", path, std::strerror(-r));
        }
    }
    ::close(fd);
    if (r) ::unlink(tmp);
    return r;
}

const char* chm_bp_last_error(void) { return t_error; }

}  // extern "C"
