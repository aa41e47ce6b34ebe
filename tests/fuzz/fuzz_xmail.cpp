// libFuzzer harness: express-mail request decoding. The input is a spawn
// request as a sender could write it into a ring record (any bytes, any
// length up to a record); xmail::decode_spawn must accept it only when
// the path and every argument are NUL-terminated strings inside it, and
// refuse the rest with a status. The request lies in a buffer of exactly
// its length, so AddressSanitizer sees any read past it.
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "ipc/xmail/xmail.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (size > 65536) return 0;
    std::vector<char> req(data, data + size);
    chm::xmail::SpawnArgs args;
    const int r = chm::xmail::decode_spawn(req.data(), std::uint32_t(size), &args);
    if (r == -EINVAL || r == -E2BIG) return 0;
    if (r != 0) std::abort();  // no other status is documented
    const char* lo = req.data() + sizeof(chm::xmail::SpawnRequest);
    const char* hi = req.data() + size;
    auto inside = [&](const char* s) { return s >= lo && s < hi && std::memchr(s, 0, std::size_t(hi - s)); };
    if (!inside(args.path) || args.argc < 0 || args.argc > chm::xmail::kSpawnArgsMax) std::abort();
    for (int i = 0; i < args.argc; ++i)
        if (!inside(args.argv[i])) std::abort();
    return 0;
}
