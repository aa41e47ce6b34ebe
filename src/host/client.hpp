// The client side of the host server (hostio.hpp): one request through
// express mail to slot 0, and the transfer segment that carries bulk data.
#pragma once

#include <cstddef>
#include <cstdint>

#include "host/hostio.hpp"
#include "ipc/xmail/xmail.hpp"

namespace chm::host {

// Send `h` (its text_len set here) followed by `text` and wait for the
// reply: its payload into reply[0..cap), its length into *reply_len (may
// be NULL). timeout_ns 0: chm_host_timeout(). Returns the server's status
// or a transport error, with chm_xfs_last_error() set on any error (the
// server's own errors are described with `what`).
int request(HostRequest h, const void* text, std::uint32_t text_len, void* reply, std::uint32_t cap,
            std::uint32_t* reply_len, const char* what, std::uint64_t timeout_ns = 0);

// request() in two halves (xmail::post / await), for the read-ahead that
// keeps several requests in flight. post_request: 0 or a transport error
// (message set); await_request: as request().
int post_request(HostRequest h, const void* text, std::uint32_t text_len, xmail::Pending* p, const char* what,
                 std::uint64_t timeout_ns = 0);
int await_request(xmail::Pending* p, void* reply, std::uint32_t cap, std::uint32_t* reply_len, const char* what);

// Bytes of text (or reply payload) one request can carry inline.
std::uint32_t inline_room();

// A buffer of this process's transfer segment, lent for one request, or
// nullptr (no segment could be made, or both buffers are lent: the caller
// moves the data inline). index is the buffer's number for HostRequest::bulk
// (1-based).
struct Bulk {
    char* data = nullptr;
    std::uint32_t index = 0;
};
Bulk bulk_take();
void bulk_give(Bulk b);

// The last error's text, for the calls of xfs.h and host.h.
void set_error(const char* fmt, ...) __attribute__((format(printf, 1, 2)));
void clear_error();

}  // namespace chm::host
