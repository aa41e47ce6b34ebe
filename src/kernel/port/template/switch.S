/* The template port: a documented, empty port/<arch>/switch.S. It owns the
 * context switch, the one piece of the contract that must be assembly, and
 * the first instruction of every new context.
 *
 *   void chm_port_switch(void **save_sp, void *load_sp)
 *
 * What it must do, in this order:
 *  1. Push, on the running (outgoing) stack, every register the ABI makes
 *     callee-saved (x86-64: rbx rbp r12-r15; aarch64: x19-x29, x30, d8-d15;
 *     m68k: d2-d7 a2-a6 fp2-fp7) and the FP control state a task may change
 *     (rounding mode, exception masks, precision: MXCSR and the x87 control
 *     word; FPCR). Sticky FP status flags are not part of a context. The
 *     return address is pushed by the call (or, on link-register machines,
 *     is in the link register, which is then one of the pushed registers).
 *  2. Store the resulting stack pointer in *save_sp.
 *  3. Load load_sp into the stack pointer.
 *  4. Pop the same set in reverse and return: into the incoming context's
 *     own call of chm_port_switch, or, for a fresh context, into
 *     chm_port_context_start (context.cpp put its address where the return
 *     address is found).
 * Pre:  load_sp came from context_init or from an earlier switch out of
 *       that context, and that context is not running; called in task or
 *       kernel context with the interrupt mask held, never in a signal
 *       handler. Caller-saved registers are dead: the compiler spilled them.
 * Post: when some context later switches back, every callee-saved integer
 *       and FP register and the FP control state are as they were at the
 *       call; the stack pointer is as it was, and nothing at or above it
 *       was touched.
 * Keep the frame a multiple of kStackAlign, and mirror its layout in
 * context.cpp as a struct with a static_assert on its size. Everything the
 * switch does not save is the kernel's business, not the port's.
 *
 *   chm_port_context_start (no arguments; reached by the first switch)
 *
 * Moves the argument and entry that context_init stored in callee-saved
 * slots into the ABI's argument register (or pushes the argument), ends the
 * frame-pointer chain (frame pointer 0, and `.cfi_undefined` for the return
 * address so unwinders stop here), and calls entry(arg) with the stack
 * aligned as at any call. entry never returns: trap after the call.
 *
 * Checked by tests/port/test_port_switch.cpp, with the helpers of
 * tests/port/<arch>/regs.S (load patterns into every callee-saved register
 * and a non-default FP control state, switch, compare).
 */
    .error  "port/template is documentation: copy it to port/<arch>/ and fill it in"

    .text
    .globl  chm_port_switch
    .type   chm_port_switch, @function
chm_port_switch:
    /* 1-4 above */
    .size   chm_port_switch, .-chm_port_switch

    .globl  chm_port_context_start
    .type   chm_port_context_start, @function
chm_port_context_start:
    /* call entry(arg); trap if it returns */
    .size   chm_port_context_start, .-chm_port_context_start

    /* No executable stack: every port's assembly says so. */
    .section .note.GNU-stack,"",@progbits
