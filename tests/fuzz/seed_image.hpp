// The seed image of the backplane harness: a small, valid backplane file
// holding one object of each kind (a shared memory segment, a remote
// semaphore, a priority message queue with two messages queued), left
// quiescent. Built the same way by the harness at start-up and by the
// corpus generator, so the committed patches name the same fields.
#pragma once

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include <fcntl.h>
#include <unistd.h>

#include "chimera/bp.h"
#include "chimera/msgq.h"
#include "chimera/rsem.h"
#include "chimera/shm.h"
#include "ipc/backplane/backplane.hpp"

namespace chm::fuzz {

struct SeedImage {
    std::vector<char> bytes;
    bp::Layout layout;
    std::uint32_t entry[3] = {};   // registry index of seg, sem, q
    std::uint32_t offset[3] = {};  // their payload offsets
};

inline void die(const char* what) {
    std::fprintf(stderr, "seed image: %s: %s\n", what, chm_bp_last_error());
    std::exit(2);
}

// Build the image at `path` (which must not exist) and read it back.
inline SeedImage make_seed_image(const char* path) {
    chm_bp_config_t c;
    chm_bp_config_init(&c);
    c.rtpu_slots = 3;
    c.ring_records = 2;
    c.ring_record_size = 128;
    c.local_window_size = 4096;
    c.common_size = 16384;
    c.registry_capacity = 4;
    if (chm_bp_create(path, &c)) die("create");
    if (chm_bp_attach_host(path, "seed", nullptr)) die("attach");
    void* seg = nullptr;
    if (chm_shm_create("seg", 256, CHM_SHM_COMMON, &seg)) die("shm");
    chm_rsem_t* sem = nullptr;
    if (chm_rsem_create("sem", CHM_SEM_COUNTING, 1, CHM_SHM_COMMON, &sem)) die("rsem");
    chm_msgq_attr_t attr;
    chm_msgq_attr_init(&attr);
    attr.order = CHM_MSGQ_PRIORITY;
    attr.max_msg = 16;
    attr.max_count = 4;
    attr.max_waiters = 2;
    chm_msgq_t* q = nullptr;
    if (chm_msgq_create("q", &attr, 1, &q)) die("msgq");  // in RTPU 1's window
    const std::uint32_t one = 1, two = 2;
    if (chm_msgq_try_send(q, 0, 3, &one, sizeof one) || chm_msgq_try_send(q, 0, 7, &two, sizeof two)) die("send");
    SeedImage s;
    const bp::Attachment* a = bp::current();
    s.layout = a->layout;
    const char* names[3] = {"seg", "sem", "q"};
    const std::uint32_t kinds[3] = {bp::kKindShm, bp::kKindRemoteSem, bp::kKindMsgQueue};
    for (int k = 0; k < 3; ++k) {
        bp::EntryInfo e{};
        if (bp::registry_lookup(*a, names[k], kinds[k], &e)) die("lookup");
        s.entry[k] = e.index;
        s.offset[k] = e.offset;
    }
    s.bytes.resize(a->size);
    if (chm_bp_leave()) die("leave");
    const int fd = ::open(path, O_RDONLY);
    if (fd < 0 || ::pread(fd, s.bytes.data(), s.bytes.size(), 0) != ssize_t(s.bytes.size())) die("read");
    ::close(fd);
    return s;
}

// A private directory for the harness's files.
inline std::string private_dir(const char* prefix) {
    // /dev/shm where it exists: the backplane harness rewrites and maps its
    // image for every input, and a disk-backed file makes that I/O.
    const char* base = std::getenv("TMPDIR");
    if (!base || !*base) base = ::access("/dev/shm", W_OK) == 0 ? "/dev/shm" : "/tmp";
    std::string t = std::string(base) + "/" + prefix + "XXXXXX";
    std::vector<char> buf(t.begin(), t.end());
    buf.push_back(0);
    if (!::mkdtemp(buf.data())) {
        std::perror("mkdtemp");
        std::exit(2);
    }
    return buf.data();
}

}  // namespace chm::fuzz
