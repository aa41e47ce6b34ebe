// Read-ahead for sequential reads of a regular host file through the
// extended file system (stream.cpp has the why and how).
#pragma once

#include <cstddef>
#include <cstdint>

namespace chm::host::stream {

// Reads of at least this many bytes are streamed; smaller ones end a stream.
inline constexpr std::size_t kMinRead = 16 * 1024;

// What open said of handle fd (a regular file may be streamed).
void opened(int fd, bool regular);
// The handle is being closed: its stream ends.
void closed(int fd);
// End fd's stream, if it has one: blocks in flight are waited for and the
// server's file position set to the reader's. Before any call on the
// handle that uses or changes its position or its data. 0, or the error
// of setting the position; -EBUSY another task held it for ~5 s.
int end(int fd);
// A read of n bytes at the position through fd's stream (started here
// when the handle is a regular file and n >= kMinRead). *used false: not
// streamed (the caller reads as usual; no stream is left running). Else
// the bytes read (0 at end of file) or -errno.
std::int64_t read(int fd, char* buf, std::size_t n, bool* used);

}  // namespace chm::host::stream
