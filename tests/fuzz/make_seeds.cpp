// Writes the seed corpora of the fuzz harnesses (tests/fuzz/corpus/, committed):
//   backplane/  patch lists over the seed image: none, and one patch per
//               field the opens check (ring geometry, slot state and kind,
//               arena header and first block, every word of each registry
//               entry, the queue's header words and first slot, the
//               semaphore's counters and first record), with values that
//               are out of range in different ways;
//   msgq/       operation programs: sends and receives on each queue;
//   xmail/      spawn requests, well formed and not.
// Usage: fuzz-make-seeds DIR (the corpus directory to fill).
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "ipc/msgq/msgq.hpp"
#include "ipc/xmail/xmail.hpp"
#include "seed_image.hpp"

namespace {

void put(const std::string& path, const std::vector<std::uint8_t>& bytes) {
    FILE* f = std::fopen(path.c_str(), "wb");
    if (!f || std::fwrite(bytes.data(), 1, bytes.size(), f) != bytes.size() || std::fclose(f) != 0) {
        std::perror(path.c_str());
        std::exit(1);
    }
}

void patch(std::vector<std::uint8_t>* out, std::uint32_t byte_off, std::uint32_t value) {
    const std::uint32_t w = byte_off / 4;
    for (int i = 0; i < 4; ++i) out->push_back(std::uint8_t(w >> (8 * i)));
    for (int i = 0; i < 4; ++i) out->push_back(std::uint8_t(value >> (8 * i)));
}

}  // namespace

int main(int argc, char** argv) {
    if (argc != 2) {
        std::fprintf(stderr, "usage: fuzz-make-seeds DIR\n");
        return 2;
    }
    const std::string dir = argv[1];
    const std::string tmp = chm::fuzz::private_dir("chm-seeds-");
    const chm::fuzz::SeedImage s = chm::fuzz::make_seed_image((tmp + "/seed.bp").c_str());
    ::unlink((tmp + "/seed.bp").c_str());
    ::rmdir(tmp.c_str());
    using namespace chm::bp;
    const Layout& l = s.layout;
    std::vector<std::uint32_t> fields;  // byte offsets of words worth changing
    for (std::uint32_t k = 0; k < 8; ++k) fields.push_back(l.regions[kRegionRings].offset + l.ring_stride + 4 * k);
    fields.push_back(l.regions[kRegionTable].offset + sizeof(RtpuEntry));      // rtpu[1].status
    fields.push_back(l.regions[kRegionTable].offset + sizeof(RtpuEntry) + 4);  // rtpu[1].kind
    for (std::uint32_t k = 0; k < 12; ++k) fields.push_back(l.regions[kRegionCommon].offset + 16 + 4 * k);  // arena header
    for (std::uint32_t k = 0; k < 8; ++k) fields.push_back(l.regions[kRegionCommon].offset + 64 + 4 * k);   // first block
    for (std::uint32_t e = 0; e < 3; ++e)
        for (std::uint32_t k = 0; k < 8; ++k)
            fields.push_back(l.regions[kRegionRegistry].offset + s.entry[e] * sizeof(RegistryEntry) + 4 * k);
    for (std::uint32_t k = 4; k < 96 + 8; ++k) fields.push_back(s.offset[2] + 4 * k);  // queue header, head/tail, slot 0
    const std::uint32_t sem = (s.offset[1] + 63) & ~63u;
    for (std::uint32_t k = 4; k < 16; ++k) fields.push_back(sem + 4 * k);  // counters, record 0
    const std::uint32_t values[] = {0, 1, 4, 0x41, 0xFFFFFFFFu, 0x80000000u, 0xFFFFFF00u};
    put(dir + "/backplane/none", {});
    unsigned n = 0;
    for (std::uint32_t f : fields) {
        std::vector<std::uint8_t> b;
        patch(&b, f, values[n % (sizeof values / sizeof values[0])]);
        char name[64];
        std::snprintf(name, sizeof name, "/backplane/patch-%04u", n++);
        put(dir + name, b);
    }
    // msgq: op byte (queue | what << 2 | type << 4), then prio and length,
    // or a buffer size.
    put(dir + "/msgq/send-recv", {0x00, 3, 8, 0x08, 0x01, 9, 40, 0x09, 0x02, 5, 0, 0x08, 0x0A, 0x0E, 4});
    put(dir + "/msgq/priorities", {0x02, 1, 4, 0x02, 31, 4, 0x02, 7, 12, 0x02, 31, 2, 0x0A, 0x0A, 0x0A, 0x0A});
    put(dir + "/msgq/full-and-oversize", {0x00, 0, 40, 0x00, 0, 40, 0x00, 0, 40, 0x00, 0, 40, 0x00, 0, 40,
                                          0x00, 0, 40, 0x00, 0, 40, 0x00, 0, 41, 0x00, 40, 1, 0x08});
    // xmail: SpawnRequest {argc, text_len}, then path NUL, args NUL.
    auto spawn = [](std::int32_t argc, const std::string& text, std::uint32_t text_len) {
        std::vector<std::uint8_t> b(8);
        std::memcpy(b.data(), &argc, 4);
        std::memcpy(b.data() + 4, &text_len, 4);
        b.insert(b.end(), text.begin(), text.end());
        return b;
    };
    const std::string t("/bin/prog.so\0a\0bc\0", 18);
    put(dir + "/xmail/ok", spawn(2, t, 18));
    put(dir + "/xmail/missing-arg", spawn(3, t, 18));
    put(dir + "/xmail/no-nul", spawn(1, std::string("/x.so\0ab", 8), 8));
    put(dir + "/xmail/long-text", spawn(0, std::string("/x.so\0", 6), 600));
    // args: NUL-separated command-line values.
    static const char kArgs[] = "5\0" "0\0" "99\0" "100\0" "-1\0" "007\0" "12x\0" "\0" "+3\0" " 4\0"
                                "9223372036854775808\0" "1023\0" "1024";
    const std::string args(kArgs, sizeof kArgs - 1);
    put(dir + "/args/values", std::vector<std::uint8_t>(args.begin(), args.end()));
    std::printf("%u backplane patches, 3 msgq programs, 4 spawn requests, 1 argument list in %s\n", n + 1, dir.c_str());
    return 0;
}
