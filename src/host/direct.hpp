// Direct reads of page-cached host files (direct.cpp has the why and how).
#pragma once

#include <cstddef>
#include <cstdint>

#include "host/hostio.hpp"

namespace chm::host::direct {

// What open replied for handle fd: with kOpenDirect, this process opens
// its own descriptor of the file (checked to be the same file).
void opened(int fd, const OpenReply& r);
// The handle is being closed: its descriptor goes too.
void closed(int fd);
// Whether handle fd has a descriptor of its own.
bool has(int fd);
// Read up to n bytes at `off` from what the page cache holds, never
// waiting for the disk: the bytes read (fewer when the cache holds fewer,
// or at the end of the file; 0 at or past the end), -EAGAIN when the
// first byte is not cached, -ENOTSUP when the handle has no descriptor.
std::int64_t read(int fd, char* buf, std::size_t n, std::uint64_t off);

// Of this process, since it started (tests, the bench): bytes read
// directly, and reads whose first byte was not cached (-EAGAIN).
struct Counts {
    std::uint64_t bytes, misses;
};
Counts counts();

}  // namespace chm::host::direct
