/* Chimera global error handling: error signals, their handlers, marks, and
 * the UNIX calls a control program uses wrapped so that, with global error
 * handling on, they need no return-value checks (the paper's `fd = open(..)`
 * with no `if`).
 *
 * An error signal is (module, code). chm_err_invoke() raises one in the
 * calling task; the runtime raises them too: processor exceptions (module
 * "cpu"), deadline misses of tasks without a deadline handler and errors the
 * kernel detects (module "kernel"), and, when the task has global handling
 * on, failed runtime calls and failed UNIX wrappers (modules "kernel" and
 * "unix").
 *
 * Handlers run in the failing task's context, and are looked up in this
 * order, each one able to pass the error on (CHM_ERR_PASS):
 *   1. the scopes the task pushed, innermost first;
 *   2. the task's handler for that (module, code);
 *   3. the task's handler for the module;
 *   4. the task's own handler;
 *   5. chm_err_default_handler: one line on stderr, the task is aborted.
 * Every task has its own set (a new task starts with none, global handling
 * off). Aborting a task ends only that task: the RTPU and its other tasks
 * keep running, and the local binary semaphores it held are released with
 * owner-died semantics (the next P returns -EOWNERDEAD, having taken the
 * semaphore).
 *
 * A fault the RTPU cannot pin on one task -- on the kernel thread outside a
 * task, inside the kernel (interrupt mask held), or inside an error handler
 * -- fail-stops the RTPU: one diagnostic line on stderr, then the process
 * exits with status CHM_ERR_FAILSTOP_STATUS. Faults on threads that are not
 * the kernel thread keep their default behaviour.
 *
 * Calling context: task context unless a function says otherwise. */
#ifndef CHIMERA_ERR_H
#define CHIMERA_ERR_H

#include "chimera/status.h"

#include <setjmp.h>
#include <stddef.h>
#include <stdint.h>
#include <sys/types.h>

#include "chimera/task.h"

#ifdef __cplusplus
extern "C" {
#endif

/* ---------------------------------------------------------------- modules */

/* Built-in modules. */
#define CHM_ERR_KERNEL 1 /* "kernel": failed runtime calls, deadline misses, corruption */
#define CHM_ERR_CPU 2    /* "cpu": processor exceptions */
#define CHM_ERR_UNIX 3   /* "unix": the UNIX wrappers below; the code is the errno value */
#define CHM_ERR_MODULES_MAX 64

/* Codes of module "kernel". A failed runtime call raises the positive errno
 * value of its status (EINVAL, ESRCH, ...); the kernel's own findings are: */
#define CHM_EK_DEADLINE 1001 /* a deadline miss of a task without a deadline handler
                              * (CHM_ERR_DEFAULT_CONTINUES) */
#define CHM_EK_HEAP 1002     /* chm_mem_check found the heap corrupt */
#define CHM_EK_CANARY 1003   /* a task's stack canary was overwritten */

/* Codes of module "cpu". Processor exceptions are fatal to the task's
 * current path (CHM_ERR_FATAL): continuing is impossible; a handler may
 * return to a mark (not after CHM_ECPU_STACK) or abort. */
#define CHM_ECPU_SEGV 1  /* SIGSEGV: a bad memory access */
#define CHM_ECPU_BUS 2   /* SIGBUS */
#define CHM_ECPU_FPE 3   /* SIGFPE: integer division by zero, FP trap */
#define CHM_ECPU_ILL 4   /* SIGILL: an illegal instruction */
#define CHM_ECPU_STACK 5 /* the task overflowed its stack (its guard page), or
                          * was preempted with too little stack left for the
                          * preemption frame (the port's kPreemptFrameMax plus
                          * 1 KiB for the scheduler): it is aborted instead of
                          * faulting inside the kernel, and the RTPU runs on */

/* The exit status of a fail-stopped RTPU process. */
#define CHM_ERR_FAILSTOP_STATUS 70

/* One code of a module and its message. */
typedef struct chm_err_code {
    int code; /* > 0 */
    const char* message;
} chm_err_code_t;

/* Register a module: its name (copied, up to 31 characters) and a table of
 * its codes with their messages (the table is kept by pointer: keep it
 * alive). Returns the module id (> 0), which chm_err_invoke takes. Any
 * context but a signal handler; modules live as long as the process.
 * Errors: -EINVAL NULL or empty name, a name too long, codes NULL with
 * ncodes > 0, a code <= 0; -EEXIST a module of that name exists;
 * -ENOSPC CHM_ERR_MODULES_MAX modules already. */
CHM_CHECK int chm_err_module_register(const char* name, const chm_err_code_t* codes, size_t ncodes);
/* The id of the module called `name`. Errors: -ENOENT; -EINVAL NULL. */
CHM_CHECK int chm_err_module_find(const char* name);
/* A module's name, or NULL for an unknown id. Any context. */
const char* chm_err_module_name(int module);
/* The message of (module, code): the module's table, else strerror() for
 * modules "kernel" and "unix", else "unknown error". Any context. */
const char* chm_err_message(int module, int code);

/* The RTPU number printed in diagnostics (default: the kernel config's
 * rtpu_id). The backplane sets it when the RTPU joins. Any context. */
void chm_err_rtpu_set(int rtpu);

/* ------------------------------------------------------------- signals */

#define CHM_ERR_FATAL 0x1u /* the failing path cannot continue */
/* The default handler continues instead of aborting: deadline misses. A
 * late cycle is no bug of the task, and aborting a servo loop for one
 * late cycle would stop the machine it drives. The default line is
 * printed for a task's 1st, 2nd, 4th, 8th... miss; a handler for
 * (CHM_ERR_KERNEL, CHM_EK_DEADLINE) may abort instead. */
#define CHM_ERR_DEFAULT_CONTINUES 0x2u

/* What a handler learns about an error signal. */
typedef struct chm_err_info {
    int module;
    int code;
    const char* module_name;
    const char* message;
    const char* call;   /* the failing call ("open", "chm_sem_p"), or NULL */
    const char* detail; /* more about it (a path, "address not mapped"), or NULL */
    const char* file;   /* where it was raised (debug builds), or NULL */
    int line;
    chm_tid_t task;     /* the failing task, CHM_TID_NONE outside a task */
    int status;         /* what the failing call returns if a handler continues */
    unsigned flags;     /* CHM_ERR_FATAL */
    uintptr_t addr;     /* processor exceptions: the faulting address */
    uintptr_t pc;       /* processor exceptions: the faulting instruction */
} chm_err_info_t;

typedef enum chm_err_action {
    CHM_ERR_CONTINUE = 0, /* the failing call returns its error status */
    CHM_ERR_ABORT = 1,    /* end the task (no message: the handler spoke) */
    CHM_ERR_TO_MARK = 2,  /* return to the task's innermost mark */
    CHM_ERR_PASS = 3      /* not mine: ask the next handler in the order */
} chm_err_action_t;

/* A handler. Runs in the failing task's context and may call anything a
 * task may. An error signal raised inside a handler goes straight to the
 * default handler (no recursion); a processor exception inside a handler
 * fail-stops the RTPU. CONTINUE after a CHM_ERR_FATAL error aborts the
 * task; TO_MARK with no mark set aborts it with the default line. */
typedef chm_err_action_t (*chm_err_handler_t)(const chm_err_info_t* info, void* arg);

/* Raise error signal (module, code) in the calling task. Returns 0 when a
 * handler continued. Outside a task the default line is printed and 0
 * returned (there is no task to abort). Errors: -EINVAL unknown module or
 * code <= 0 (nothing raised). */
int chm_err_invoke(int module, int code);
/* The same, recording where. CHM_ERR_INVOKE uses it in debug builds.
 * Errors: as chm_err_invoke. */
int chm_err_invoke_at(int module, int code, const char* file, int line);
#ifdef NDEBUG
#define CHM_ERR_INVOKE(module, code) chm_err_invoke_at((module), (code), NULL, 0)
#else
#define CHM_ERR_INVOKE(module, code) chm_err_invoke_at((module), (code), __FILE__, __LINE__)
#endif

/* The default handler: writes one line to stderr --
 *   chimera: RTPU 1 task ctrl (id 65537): unix error 2 (No such file or
 *   directory) in open("/x") at main.c:12
 * -- and returns CHM_ERR_ABORT. Handlers may call it to print the same. */
chm_err_action_t chm_err_default_handler(const chm_err_info_t* info, void* arg);

/* ------------------------------------------------------------- handlers */

/* Install (h non-NULL) or remove (h NULL) the calling task's handler for
 * (module, code), for a whole module, or for all its errors.
 * Errors: -EPERM not in a task; -EINVAL unknown module or code <= 0;
 * -ENOSPC 32 code and module handlers already; -ENOMEM. */
CHM_CHECK int chm_err_on_code(int module, int code, chm_err_handler_t h, void* arg);
CHM_CHECK int chm_err_on_module(int module, chm_err_handler_t h, void* arg);
CHM_CHECK int chm_err_on_task(chm_err_handler_t h, void* arg);

/* A scope: a region of code with its own handler, nestable. The scope
 * object lives in the caller (its stack) until it is popped. */
typedef struct chm_err_scope {
    void* opaque[4];
} chm_err_scope_t;
/* Enter a scope: `h` sees every error signal raised in the task until the
 * matching pop (before any code, module or task handler).
 * Errors: -EPERM not in a task; -EINVAL NULL; -ENOMEM. */
CHM_CHECK int chm_err_scope_push(chm_err_scope_t* scope, chm_err_handler_t h, void* arg);
/* Leave the innermost scope, which must be `scope`. Errors: -EPERM; -EINVAL
 * not the innermost scope. */
CHM_CHECK int chm_err_scope_pop(chm_err_scope_t* scope);

/* ---------------------------------------------------------------- marks */

/* A place to return to, setjmp-like. Lives in the caller's frame. */
typedef struct chm_err_mark {
    jmp_buf jb;
    void* link[3];
    unsigned magic;
    int code;
    int depth;
} chm_err_mark_t;

/* Mark this place: `chm_err_mark(&m)` evaluates to 0 when the mark is set
 * and to the error code when a handler returned CHM_ERR_TO_MARK (or
 * chm_err_jump was called). The mark becomes the task's innermost one; the
 * scopes pushed after it are popped by a return to it. It stays set until
 * chm_err_unmark, which the function that set it must call before it
 * returns (as with setjmp, returning to a dead frame is undefined). Like
 * setjmp, use it only as a whole condition or statement, and make locals
 * changed after it `volatile` if they are read after a return. Green-thread
 * safe: the mark belongs to the task and its stack. Task context. */
#define chm_err_mark(m) setjmp(*chm_err_mark_arm_(m))
jmp_buf* chm_err_mark_arm_(chm_err_mark_t* m); /* for the macro */
/* Remove mark `m` (and any marks set after it). Errors: -EPERM; -EINVAL
 * not a mark of this task. */
CHM_CHECK int chm_err_unmark(chm_err_mark_t* m);
/* Return to mark `m` of the calling task with `code` (> 0) as the value of
 * its chm_err_mark. Does not return; with `m` not a live mark of the task,
 * the task is aborted with a kernel EINVAL line. */
void chm_err_jump(chm_err_mark_t* m, int code)
#if defined(__GNUC__)
    __attribute__((noreturn))
#endif
    ;

/* --------------------------------------------------- global handling */

/* Switch global error handling of the calling task on (1) or off (0); it
 * starts off. When on, runtime calls (chm_task_*, chm_sem_*, chm_err_*,
 * chm_mem_check) that fail with a status meaning a bug or a missing
 * resource -- -EINVAL, -ESRCH, -EPERM, -ENOMEM, -ENAMETOOLONG, -ENOSPC,
 * -EEXIST, -ENOENT, -EBADF, -EFAULT -- raise module "kernel" (code the
 * errno value; -EFAULT of chm_mem_check raises CHM_EK_HEAP) and the UNIX
 * wrappers below raise module "unix" on every failure. Outcome statuses
 * (-ETIMEDOUT, -EINTR, -EAGAIN, -EIDRM, -EOVERFLOW, -EOWNERDEAD) are always
 * just returned. A call whose handler continued returns its status as
 * when off. Returns the previous setting. Errors: -EPERM not in a task;
 * -ENOMEM. */
CHM_CHECK int chm_err_global(int on);
/* Returns the calling task's setting (0 outside a task). Never fails. */
int chm_err_global_get(void);

/* The UNIX calls, wrapped: exactly the libc call when global handling is
 * off or it succeeds (-1 or NULL with errno set on failure, like UNIX); a
 * "unix" error signal with code errno on failure when it is on. errno is
 * kept across the handler. A failure also leaves chm_err_last() naming the
 * call, its path (open) and the cause. Also usable outside tasks (never
 * raising). Errors: those of the libc call, in errno. */
CHM_CHECK int chm_unix_open(const char* path, int flags, ...);
CHM_CHECK int chm_unix_close(int fd);
CHM_CHECK ssize_t chm_unix_read(int fd, void* buf, size_t n);
CHM_CHECK ssize_t chm_unix_write(int fd, const void* buf, size_t n);
off_t chm_unix_lseek(int fd, off_t off, int whence);
CHM_CHECK int chm_unix_ioctl(int fd, unsigned long request, ...);
/* chm_malloc (chimera/mem.h) whose NULL raises "unix" ENOMEM when on. */
void* chm_unix_malloc(size_t size);

/* The names before API 1.0 (chm_open beside chm_dev_open read as the same
 * subsystem): the same calls, kept for one release (CHANGELOG.md). Errors:
 * as chm_unix_open and the others. */
CHM_CHECK int chm_open(const char* path, int flags, ...);
CHM_CHECK int chm_close(int fd);
CHM_CHECK ssize_t chm_read(int fd, void* buf, size_t n);
CHM_CHECK ssize_t chm_write(int fd, const void* buf, size_t n);
off_t chm_lseek(int fd, off_t off, int whence);
CHM_CHECK int chm_ioctl(int fd, unsigned long request, ...);
void* chm_malloc_checked(size_t size);

/* ------------------------------------------------------------- last error */

/* Longest last-error text kept, with its terminating NUL. */
#define CHM_ERR_LAST_MAX 256

/* The text of the calling task's last error, whatever subsystem raised it:
 * a failing call of the kernel, the backplane and its IPC, express mail
 * and RTPU control, devices, programs, host files and calls, configuration
 * files, matrices, servo modules, the command interpreter or the UNIX
 * wrappers leaves here what went wrong, naming the call and what it was
 * given; a failure with nothing more to say leaves "call: <strerror of the
 * status>". Per task: the tasks of an RTPU never see each other's. Outside
 * a task, per thread. It stays until the task's next failing call (a call
 * that succeeds leaves it). Never NULL: "" before the first error. The
 * text belongs to the task; copy it to keep it past the task's end.
 * Any context but a signal handler. */
const char* chm_err_last(void);

/* Make the printf-style text the calling task's last error (libraries and
 * control modules built on Chimera, so that their failures read like
 * Chimera's own); at most CHM_ERR_LAST_MAX - 1 bytes are kept. NULL fmt
 * does nothing. Any context but a signal handler. */
void chm_err_set_last(const char* fmt, ...) __attribute__((format(printf, 1, 2)));

#ifdef __cplusplus
}
#endif
#endif /* CHIMERA_ERR_H */
