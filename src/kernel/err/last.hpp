// The last error's text (err/last.cpp, chm_err_last), for the subsystems
// that set it: a subsystem's message for the call that is failing
// (err_last_set), and a failure exit's record (err_last_failed: "call:
// strerror(status)" unless `keep_set` and a message was set since the last
// exit). Task or thread context, the interrupt mask may be held; never from
// a signal handler.
#pragma once

namespace chm::kernel {

void err_last_set(const char* text);
void err_last_failed(const char* call, int status, bool keep_set);

}  // namespace chm::kernel
