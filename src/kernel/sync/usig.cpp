// User signals between tasks of one RTPU: a pending bit per signal; the
// handler runs in the target's context when it next runs (the dispatcher's
// deliver_pending_locked), and an interruptible wait returns -EINTR.
#include <cerrno>

#include "kernel.hpp"
#include "err/err_internal.hpp"

using namespace chm::kernel;
namespace port = chm::port;

extern "C" {

int chm_usig_handle(int signo, chm_usig_handler_t handler, void* arg) {
    if (signo < 1 || signo > CHM_USIG_MAX) return record_failure(-EINVAL, "chm_usig_handle");
    IrqGuard guard;
    Tcb* cur = g_k.current;
    if (!cur) return record_failure(-EPERM, "chm_usig_handle");
    cur->sig_handler[signo] = handler;
    cur->sig_arg[signo] = arg;
    cur->sig_handled |= 1u << signo;
    return 0;
}

int chm_usig_send(chm_tid_t task, int signo) {
    if (signo < 1 || signo > CHM_USIG_MAX) return record_failure(-EINVAL, "chm_usig_send");
    IrqGuard guard;
    Tcb* t = tcb_lookup(task);
    if (!t) return record_failure(-ESRCH, "chm_usig_send");
    t->sig_pending |= 1u << signo;
    if (t->sig_blocked & (1u << signo)) return 0;
    if (t->interruptible) {
        if (t->state == TaskState::WaitPeriod) {
            // Keep the release timer: the release still comes on the grid.
            t->interruptible = false;
            t->wait_result = -EINTR;
            make_ready_locked(t);
        } else if (t->state == TaskState::Blocked || t->state == TaskState::Paused) {
            wake_locked(t, -EINTR);
        }
    }
    reschedule_locked();
    return 0;
}

uint32_t chm_usig_mask(uint32_t mask, int block) {
    IrqGuard guard;
    Tcb* cur = g_k.current;
    if (!cur) return 0;
    const std::uint32_t old = cur->sig_blocked;
    cur->sig_blocked = block ? (old | mask) : (old & ~mask);
    if (!block) deliver_pending_locked();
    return old;
}

}  // extern "C"
