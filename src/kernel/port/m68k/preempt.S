/* m68k preemption trampoline. The timer handler pushed the interrupted PC
 * and, above it in pop order, the interrupted CCR on the task's stack and
 * pointed the task here (m68k/preempt.cpp). We save everything the
 * interrupted code may have live -- d0-d7, a0-a6, fp0-fp7 (full 96-bit
 * images) and FPCR, FPSR, FPIAR -- call the kernel through
 * chm_port_preempt_hook (the C call preserves d2-d7/a2-a6/fp2-fp7 by the
 * ABI, but we restore all of them anyway from one frame), restore, and
 * return with `rtr`, which pops the CCR and the PC in one instruction.
 *
 * Frame below the interrupted sp (176 bytes at most, kPreemptFrameMax):
 *   [fpcr fpsr fpiar: 12] [fp0-fp7: 96] [d0-d7 a0-a6: 60] [ccr: 2] [pc: 4]
 *   plus up to 2 bytes to realign sp to 4 for the call.
 *
 * The FP control registers go through d0-d2 rather than fmovem.l to
 * memory: qemu 7.2 reverses FPCR and FPIAR in that form (see switch.S). */
    .text
    .globl  chm_port_preempt_trampoline
    .type   chm_port_preempt_trampoline, @function
    .p2align 2
chm_port_preempt_trampoline:
    movem.l %d0-%d7/%a0-%a6, -(%sp)
    fmovem.x %fp0-%fp7, -(%sp)      /* changes no FPSR bit */
    fmove.l %fpcr, %d0
    fmove.l %fpsr, %d1
    fmove.l %fpiar, %d2
    movem.l %d0-%d2, -(%sp)
    move.l  %sp, %a2                /* callee-saved: survives the hook */
    move.l  %sp, %d0
    and.l   #-4, %d0                /* the pushes above left sp 2 mod 4 */
    move.l  %d0, %sp
    sub.l   %a6, %a6                /* end the frame-pointer chain */
    /* The hook is hidden: the GOT reaches it in the static library and in
     * libchimera.so alike, as GCC's own -fPIC code does. */
    lea     (%pc, _GLOBAL_OFFSET_TABLE_@GOTPC), %a5
    move.l  chm_port_preempt_hook@GOT(%a5), %a0
    move.l  (%a0), %a0
    jsr     (%a0)
    move.l  %a2, %sp
    movem.l (%sp)+, %d0-%d2
    fmovem.x (%sp)+, %fp0-%fp7
    fmove.l %d0, %fpcr
    fmove.l %d1, %fpsr
    fmove.l %d2, %fpiar
    movem.l (%sp)+, %d0-%d7/%a0-%a6
    rtr
    .size   chm_port_preempt_trampoline, .-chm_port_preempt_trampoline

    .section .note.GNU-stack,"",@progbits
