// libFuzzer harness: the backplane image (issue 15 item 4). The input is a
// list of 8-byte patches, each a little-endian word offset (taken modulo
// the image's words) and the 32-bit value stored there, applied to the
// valid seed image (seed_image.hpp). The patched image is written to a
// private file, then: the checker runs on it read-only (as chimera-bpcheck
// does), chm_bp_validate runs, and a host attaches, opens every object the
// registry names and does a non-blocking operation on each (shm attach and
// a read of its first and last byte, try-P and V, try-send and
// try-receive). Anything may fail with a status; nothing may crash, hang
// or trip a sanitizer. Every slot that is not free names a live canary
// process (canary.hpp), and a patch value kCanaryWord stands for its pid:
// no input may get it signalled.
//
// Patches rather than raw bytes: the image is ~50 KiB, and a word store
// anywhere in it is what a stray write or a damaged file looks like.
#include <cstring>

#include "chimera/bp.h"
#include "chimera/msgq.h"
#include "chimera/rsem.h"
#include "chimera/shm.h"
#include "ipc/backplane/backplane.hpp"
#include "canary.hpp"
#include "seed_image.hpp"

namespace {

chm::fuzz::SeedImage g_seed;
chm::fuzz::Canary g_canary;
// A patch value that means "the canary's pid", so inputs can plant it in
// any field (waiter records, lock owners, express-mail records).
constexpr std::uint32_t kCanaryWord = 0xCA4A21E5;
std::string g_dir, g_path;
int g_fd = -1;

void open_objects() {
    using namespace chm::bp;
    Attachment* a = current();
    // Grants ring a waiter's RTPU with a directed signal; every other
    // slot names the canary (plant), which must survive (checked after
    // each input).
    for (std::uint32_t i = 0; i < a->geo().registry_capacity; ++i) {
        const RegistryEntry* e = a->entry(i);
        if (e->state.load() != std::uint32_t(EntryState::Live)) continue;
        char name[kNameMax + 1];
        read_name(e, name);
        switch (e->kind.load()) {
        case kKindShm: {
            void* p = nullptr;
            size_t n = 0;
            if (chm_shm_attach(name, &p, &n) == 0) {
                volatile const char* c = static_cast<const char*>(p);
                (void)c[0];
                (void)c[n - 1];
                chm_shm_detach(p);
            }
            break;
        }
        case kKindRemoteSem: {
            chm_rsem_t* s = nullptr;
            if (chm_rsem_open(name, &s) == 0) {
                if (chm_rsem_try_p(s) == 0) chm_rsem_v(s);
                chm_rsem_value(s);
                chm_rsem_close(s);
            }
            break;
        }
        case kKindMsgQueue: {
            chm_msgq_t* q = nullptr;
            if (chm_msgq_open(name, &q) == 0) {
                char buf[64];
                chm_msgq_msg_info_t info;
                chm_msgq_try_receive(q, buf, sizeof buf, &info);
                chm_msgq_try_send(q, 1, 5, "fuzz", 4);
                chm_msgq_try_receive(q, buf, sizeof buf, &info);
                chm_msgq_info_t st;
                chm_msgq_info(q, &st);
                chm_msgq_close(q);
            }
            break;
        }
        default:
            break;
        }
    }
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
    g_dir = chm::fuzz::private_dir("chm-fuzz-bp-");
    g_seed = chm::fuzz::make_seed_image((g_dir + "/seed.bp").c_str());
    ::unlink((g_dir + "/seed.bp").c_str());
    g_path = g_dir + "/image.bp";
    g_canary = chm::fuzz::start_canary();
    std::atexit([] {  // a clean end leaves nothing behind (a crash leaves the image to look at)
        ::unlink(g_path.c_str());
        ::rmdir(g_dir.c_str());
    });
    g_fd = ::open(g_path.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
    if (g_fd < 0) {
        std::perror("image");
        std::exit(2);
    }
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    std::vector<char> img = g_seed.bytes;
    const std::uint32_t words = std::uint32_t(img.size() / 4);
    for (std::size_t k = 0; k + 8 <= size; k += 8) {
        std::uint32_t off, val;
        std::memcpy(&off, data + k, 4);
        std::memcpy(&val, data + k + 4, 4);
        if (val == kCanaryWord) val = std::uint32_t(g_canary.pid);
        std::memcpy(&img[std::size_t(off % words) * 4], &val, 4);
    }
    chm::fuzz::plant(img.data(), g_seed.layout, g_canary);
    if (::pwrite(g_fd, img.data(), img.size(), 0) != ssize_t(img.size())) std::abort();  // always the seed's size

    // The checker, read-only, as chimera-bpcheck runs it.
    chm::bp::View v;
    int fd = -1;
    char why[320];
    if (chm::bp::map_file(g_path.c_str(), false, &v, &fd, why, sizeof why, false) == 0) {
        chm::bp::Report rep;
        chm::bp::check_backplane(v, rep, nullptr);
        chm::bp::unmap(&v);
        ::close(fd);
    }
    chm_bp_validate(g_path.c_str());
    if (chm_bp_attach_host(g_path.c_str(), "fuzz", nullptr) == 0) {
        open_objects();
        chm_bp_leave();
    }
    chm::fuzz::alive_or_abort(g_canary, "this input");
    return 0;
}
