// libFuzzer harness: the host server's request decoding (src/host/server),
// the part of chimera-rtpu --host-server that reads what any backplane
// member wrote into slot 0's ring. Each input is a sequence of requests
// (2-byte length, then that many bytes: a HostRequest and its text), served
// one after another by the same server state, as from two client slots, in
// a private root. Checked beyond AddressSanitizer: no reply longer than a
// ring record (serve_local aborts), and nothing outside the root is created
// or changed (a canary file beside the root, and its directory's entries).
// Not fuzzed: kRun (it would run programs the input names) and ioctl
// requests other than FIONREAD (some change file attributes).
#include <sys/ioctl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "../private_dir.hpp"
#include "seed_image.hpp"  // chm::fuzz::private_dir: the harnesses' scratch directory
#include "host/hostio.hpp"
#include "host/server/server.hpp"

namespace {

constexpr std::uint32_t kRoom = 1024 - 64;
std::string g_dir, g_canary;
struct stat g_canary_st;

// Whatever the fuzzed requests made under the root goes with it.
void remove_dir() { chm::test::remove_private_dir(g_dir); }

void setup() {
    g_dir = chm::fuzz::private_dir("chimera-fuzz-host-");
    std::atexit(remove_dir);
    const std::string root = g_dir + "/root";
    mkdir(root.c_str(), 0700);
    mkdir((root + "/sub").c_str(), 0700);
    if (FILE* f = std::fopen((root + "/a.txt").c_str(), "w")) std::fputs("some host file\n", f), std::fclose(f);
    g_canary = g_dir + "/canary";
    if (FILE* f = std::fopen(g_canary.c_str(), "w")) std::fputs("outside\n", f), std::fclose(f);
    symlink("../canary", (root + "/out").c_str());
    stat(g_canary.c_str(), &g_canary_st);
    chm::host::server::Options o;
    o.root = root.c_str();
    if (chm::host::server::start_local(o, kRoom) != 0) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    static bool ready = (setup(), true);
    (void)ready;
    std::vector<char> rep(kRoom);
    std::size_t at = 0;
    for (int k = 0; k < 16 && at + 2 <= size; ++k) {
        const std::size_t len = std::min<std::size_t>(std::size_t(data[at]) | std::size_t(data[at + 1]) << 8,
                                                      size - at - 2);
        at += 2;
        std::vector<char> req(data + at, data + at + len);  // exactly its length: ASan sees overreads
        at += len;
        if (len >= sizeof(chm::host::HostRequest)) {
            chm::host::HostRequest h;
            std::memcpy(&h, req.data(), sizeof h);
            if (h.op == chm::host::kRun || h.op == chm::host::kIn) continue;  // runs programs / waits for a console
            if (h.op == chm::host::kIoctl && h.b != FIONREAD) continue;
        }
        std::uint32_t n = 0;
        const std::uint32_t owner = (k & 1) ? 0x02000001u : 0x03000001u;  // two client slots
        chm::host::server::serve_local(req.data(), std::uint32_t(len), owner, rep.data(), &n);
    }
    struct stat st;
    if (stat(g_canary.c_str(), &st) != 0 || st.st_size != g_canary_st.st_size ||
        st.st_mtim.tv_sec != g_canary_st.st_mtim.tv_sec || st.st_mtim.tv_nsec != g_canary_st.st_mtim.tv_nsec)
        std::abort();  // written through an escape
    if (chm::test::private_dir_entries(g_dir).size() != 2) std::abort();  // something created beside the root
    return 0;
}
