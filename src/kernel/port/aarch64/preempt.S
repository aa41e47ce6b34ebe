/* aarch64 preemption trampoline. The timer handler copied its own signal
 * frame (siginfo + ucontext: every register, NZCV, the FP/SIMD registers,
 * FPSR, FPCR, the signal mask, the interrupted PC and SP) onto the task's
 * stack and pointed the task here with sp at that copy (preempt.cpp). The
 * interrupted state is already safe in the copy, so we may clobber any
 * register: call the kernel through chm_port_preempt_hook, and when the task
 * is scheduled again resume it with rt_sigreturn on the copy, exactly as the
 * kernel would have resumed it from the handler. */
    .text
    .globl  chm_port_preempt_trampoline
    .type   chm_port_preempt_trampoline, %function
    .p2align 4
chm_port_preempt_trampoline:
    .cfi_startproc
    .cfi_undefined x30              /* not called: unwinders stop here */
    mov     x29, xzr                /* end the frame-pointer chain as well */
    /* sp = the copied frame, 16-byte aligned: a valid call stack already.
     * The hook is hidden, so a PC-relative load reaches it in the static
     * library and in libchimera.so alike. */
    adrp    x16, chm_port_preempt_hook
    ldr     x16, [x16, :lo12:chm_port_preempt_hook]
    blr     x16
    mov     x8, #139                /* __NR_rt_sigreturn */
    svc     #0
    brk     #0x3c                   /* rt_sigreturn does not return */
    .cfi_endproc
    .size   chm_port_preempt_trampoline, .-chm_port_preempt_trampoline

    .section .note.GNU-stack,"",%progbits
