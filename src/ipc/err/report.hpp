// Global error handling of the IPC calls (chimera/err.h): the one exit of
// every public remote-semaphore, message-queue, shared-memory and spin-lock
// call. A failing status that means a bug or a missing resource becomes an
// error signal of module "ipc" (code = the errno value) when the calling
// task has global handling on; outcomes (a timeout, a full queue, an
// interrupted wait, an owner that died, an object destroyed under the
// caller) never raise. Called with the call's result, after every
// backplane lock it took is released, so a handler may abort the task or
// jump to a mark safely.
#pragma once

namespace chm::ipc {

int leave_failed(int status, const char* call);

// `status` unchanged (when off, or when a handler continues). The success
// path costs one predictable branch.
inline int leave(int status, const char* call) {
    if (status >= 0) [[likely]] return status;
    return leave_failed(status, call);
}

}  // namespace chm::ipc
