/* The template port: a documented, empty port/<arch>/preempt.S. It owns the
 * preemption trampoline, the code a preempted task runs on its own stack
 * after the timer handler returned (see redirect_to_preempt_from_signal in
 * preempt.cpp and the "preemption" section of port.hpp).
 *
 *   chm_port_preempt_trampoline (reached by sigreturn, not by a call)
 *
 * What it must do:
 *  1. Save every register the interrupted code may have live: all integer
 *     registers but the stack pointer, the condition flags, the whole FP /
 *     SIMD register file and its control and status registers. Nothing is
 *     dead at an arbitrary instruction.
 *  2. Align the stack as at a call and call through chm_port_preempt_hook
 *     (hidden; reach it PC-relative so the code also works inside
 *     libchimera.so). The hook returns, with the mask released, when the
 *     kernel schedules this task again -- possibly much later, after other
 *     tasks ran and changed every register.
 *  3. Restore everything from step 1 and resume at the interrupted PC with
 *     the interrupted stack pointer, in one step that changes no register
 *     after the restore (ret + pop on x86-64, rtr on m68k, rt_sigreturn on
 *     an interrupted-state copy on aarch64).
 * Pre:  entered with the interrupted registers (the kernel restored them at
 *       sigreturn) except PC and SP as redirect_to_preempt_from_signal set
 *       them; interrupt mask held (nest == 1); signals unblocked as in the
 *       interrupted code.
 * Post: the interrupted code continues as if nothing happened.
 *
 * Checked by tests/port/test_port_preempt.cpp, with chm_test_preempt_spin
 * in tests/port/<arch>/regs.S: load patterns into every register and the
 * flags, spin while a 50 us timer preempts, compare.
 */
    .error  "port/template is documentation: copy it to port/<arch>/ and fill it in"

    .text
    .globl  chm_port_preempt_trampoline
    .type   chm_port_preempt_trampoline, @function
chm_port_preempt_trampoline:
    /* 1-3 above */
    .size   chm_port_preempt_trampoline, .-chm_port_preempt_trampoline

    .section .note.GNU-stack,"",@progbits
