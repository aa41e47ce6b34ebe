// What the rest of the kernel needs from global error handling (err/): the
// per-task handler set, the one helper every failing runtime call returns
// through, the hooks at task end, and the processor-exception entry.
#pragma once

#include <cstdint>

#include "chimera/err.h"
#include "kernel.hpp"
#include "kernel/err/last.hpp"

namespace chm::kernel {

// One task's error-handling state, allocated on first use (most tasks never
// touch it) and freed when the task ends. Only its owner task reads or
// writes it, except the fault handler, which reads `depth`.
struct ErrScope {  // the layout of chm_err_scope_t
    ErrScope* outer;
    chm_err_handler_t h;
    void* arg;
    void* self;  // == this while pushed
};
static_assert(sizeof(ErrScope) <= sizeof(chm_err_scope_t));

// The last error of a task (or a thread): a subsystem's message, or a
// failing call and its status, formatted when read.
struct LastError {
    char text[CHM_ERR_LAST_MAX] = {};
    const char* call = nullptr;  // non-null: text is "call: strerror(status)", not made yet
    int status = 0;
    bool fresh = false;          // text set since the last failure exit
};

struct ErrBinding {  // a code handler (code > 0) or a module handler (code 0)
    int module = 0;
    int code = 0;
    chm_err_handler_t h = nullptr;
    void* arg = nullptr;
};

struct ErrTask {
    static constexpr int kBindings = 32;
    bool global = false;
    volatile int depth = 0;  // > 0 while a handler runs
    ErrScope* scope = nullptr;
    chm_err_mark_t* mark = nullptr;
    chm_err_handler_t task_h = nullptr;
    void* task_arg = nullptr;
    int nbind = 0;
    ErrBinding bind[kBindings];
    LastError last;  // chm_err_last (err/last.cpp)
};

// The task's state, allocated if `create` (nullptr when out of memory).
ErrTask* err_task(Tcb* t, bool create);

// Raise an error signal in the current task and apply the handlers'
// decision. Returns info.status when a handler continues; does not return
// when the task is aborted or returned to a mark. Task context, mask free.
int err_raise(chm_err_info_t& info);

// The one exit of a failing runtime call: `status` < 0 is raised as module
// "kernel" when the calling task has global handling on and the status is
// an error (not an outcome such as -ETIMEDOUT). Returns `status` (when
// off, or when a handler continued). The caller may hold the mask once
// (nest == 1, its own IrqGuard): it is released around the handlers.
int err_call_failed(int status, const char* call);
// A failure that never raises (a lookup that found nothing, a call outside
// its context): only chm_err_last records it.
inline int record_failure(int status, const char* call) {
    err_last_failed(call, status, false);
    return status;
}
inline int raise_or_return(int status, const char* call) {
    if (status >= 0) [[likely]] return status;
    return err_call_failed(status, call);
}

// End the current task because of an error: its held binary semaphores
// are released with owner-died semantics. Does not return. Task context.
[[noreturn]] void err_abort_current();

// Hook of task_end_locked: frees the task's error state, releases or
// detaches the semaphores it held, checks its stack canary.
void err_task_ended_locked(Tcb* t);

// Hooks of chm_kernel_init / chm_kernel_fini (on the kernel thread):
// processor-exception handlers and the fault stacks.
int err_kernel_init();
void err_kernel_fini();

// A deadline miss of a task without a deadline handler, delivered in its
// context (deliver_pending_locked): raises kernel CHM_EK_DEADLINE. Called
// with the mask held; releases it around the handlers.
void err_deadline_missed_locked(const chm_deadline_info_t& info);

// Release (owner_died) or just forget (a normal end) the binary
// semaphores `t` holds (sync/sem.cpp). Mask held.
void sem_release_held_locked(Tcb* t, bool owner_died);

// Async-signal-safe formatting of the one diagnostic line (err/line.cpp).
struct LineBuf {
    char s[512];
    unsigned n = 0;
    void put(const char* p);
    void num(long long v);
    void hex(std::uintptr_t v);
};
void err_format_line(LineBuf& b, const chm_err_info_t& info, const char* task_name);
int err_rtpu();

}  // namespace chm::kernel
