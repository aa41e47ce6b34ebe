/* Chimera interrupts: C handlers for mailbox interrupts, bus interrupts
 * (IRQ) and local interrupts (LRQ).
 *
 * Vectors 0..31 are mailbox interrupts: raised by any thread of this
 * process (chm_irq_raise) or by another RTPU or host process through the
 * backplane; all 32 are multiplexed on one doorbell word and one signal.
 * Vectors 32..63 are lines: a device's file descriptor bound with
 * chm_irq_attach_fd raises its line while it is ready (level-triggered,
 * like a hardware line: the handler must consume what made it ready, e.g.
 * read the descriptor), and a simulated device may raise a line from its
 * own thread with chm_irq_raise.
 *
 * Handlers run in interrupt context: on the kernel thread, interrupt mask
 * held, at most one at a time, before any task resumes. They may call
 * chm_sem_v, chm_usig_send and other calls that do not wait; a call that
 * would block returns -EPERM there. A task made ready by a handler runs as
 * soon as the handler returns if it is the most urgent. */
#ifndef CHIMERA_IRQ_H
#define CHIMERA_IRQ_H

#include "chimera/status.h"

#ifdef __cplusplus
extern "C" {
#endif

#define CHM_IRQ_VECTORS 64
#define CHM_IRQ_MAILBOX_FIRST 0  /* 0..31: mailbox interrupts */
#define CHM_IRQ_LINE_FIRST 32    /* 32..63: IRQ and LRQ lines */

typedef void (*chm_irq_handler_t)(int vector, void* arg);

/* Install `handler` on `vector`; the vector starts enabled. Raises that
 * came before a handler was installed are kept and delivered now.
 * Kernel thread (before chm_kernel_run) or a task.
 * Errors: -EINVAL vector out of range or handler NULL; -EBUSY a handler is
 * installed already (remove it first); -EPERM no kernel. */
CHM_CHECK int chm_irq_install(int vector, chm_irq_handler_t handler, void* arg);

/* Remove the handler of `vector` (and its descriptor, if any); raises then
 * stay pending until a handler is installed. Errors: -EINVAL bad vector;
 * -ENOENT no handler installed. */
CHM_CHECK int chm_irq_remove(int vector);

/* Disable / enable delivery on `vector`. Raises while disabled stay
 * pending (one pending raise per vector, as on a real line) and are
 * delivered on enable. Errors: -EINVAL bad vector. */
CHM_CHECK int chm_irq_disable(int vector);
CHM_CHECK int chm_irq_enable(int vector);

/* Raise `vector` from any thread of this process, or from a signal
 * handler. Errors: -EINVAL bad vector. */
CHM_CHECK int chm_irq_raise(int vector);

/* Bind line `vector` (32..63) to descriptor `fd`: the line is raised while
 * poll(2) reports any of `events` (or an error/hang-up) on it. An idle
 * RTPU sleeps on the descriptor; a busy one polls it every io_poll_ns.
 * Up to 32 bound descriptors. Errors: -EINVAL not a line vector, fd < 0
 * or events 0; -EBUSY the line already has a descriptor; -ENOSPC. */
CHM_CHECK int chm_irq_attach_fd(int vector, int fd, short events);

/* Unbind the descriptor of line `vector`. Errors: -EINVAL; -ENOENT none. */
CHM_CHECK int chm_irq_detach_fd(int vector);

/* Mask every interrupt of the calling RTPU, the timer's included (so the
 * caller is not preempted either), until the matching chm_irq_unlock;
 * pairs nest. Interrupts raised meanwhile stay pending and are delivered
 * at the outermost unlock. For a driver that shares data (or a lock) with
 * its interrupt handler: keep the section short and never block in it.
 * Called off the RTPU's kernel thread (a host process, another thread),
 * both calls do nothing. No errors. */
void chm_irq_lock(void);
void chm_irq_unlock(void);

/* Number of times `vector`'s handler ran (statistics, tests). */
unsigned long chm_irq_count(int vector);

#ifdef __cplusplus
}
#endif
#endif
