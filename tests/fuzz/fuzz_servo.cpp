// libFuzzer harness: the RTPU's decoding of servo requests (express mail
// of kind kServo, src/ipc/servo/serve.cpp). Input: the sender's token (4
// bytes), then the request as it would lie in a record. Every count,
// length and name must be checked against the bytes received: no read
// outside the request, no write outside the reply, a failure's text
// NUL-terminated inside the reply. Spawn requests are skipped: their path
// is loaded as code (after the trust check, tested elsewhere).
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "ipc/servo/servo.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    if (size < 4) return 0;
    std::uint32_t from;
    std::memcpy(&from, data, 4);
    // An exact-size copy: AddressSanitizer sees any read past the request.
    std::vector<char> req(data + 4, data + size);
    if (req.size() >= 4) {
        std::uint32_t op;
        std::memcpy(&op, req.data(), 4);
        if (op == chm::servo::kSpawn) return 0;
    }
    constexpr std::uint32_t kRoom = 960;
    std::vector<char> rep(kRoom);
    std::uint32_t n = 0;
    const int r = chm::servo::serve(req.data(), std::uint32_t(req.size()), rep.data(), kRoom, &n, from);
    if (n > kRoom) std::abort();
    if (r < 0 && n > 0 && !std::memchr(rep.data(), 0, n)) std::abort();  // the refusal's text, terminated
    return 0;
}
