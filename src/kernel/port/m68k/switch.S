/* m68k context switch (SVR4/Linux m68k ABI, 68020+ with a 68881/68882).
 * Saves what a callee must preserve: d2-d7, a2-a6 (a6 is the frame pointer,
 * callee-saved like the others), fp2-fp7 (all 96 bits of each extended
 * register image) and the FPCR (rounding mode and precision, exception
 * enables). The FPSR holds condition codes and sticky status only and is
 * not part of a context; the SR cannot be touched in user mode and its CCR
 * is not preserved across calls. d0-d1, a0-a1 and fp0-fp1 are caller-saved.
 *
 *   void chm_port_switch(void **save_sp, void *load_sp)   4(sp), 8(sp)
 *
 * Frame on the suspended stack, 120 bytes, low to high:
 *   [fpcr:4] [fp2 .. fp7: 6 x 12] [d2-d7 a2-a6: 11 x 4] <return address>
 * fmovem writes fp2 lowest; movem with -(sp) writes d2 lowest.
 *
 * The FPCR travels through d0 (caller-saved) rather than with
 * `fmove.l %fpcr,-(%sp)`: qemu 7.2 gets the memory forms of FP control
 * register moves wrong (the predecrement form stores FPIAR when asked for
 * FPCR; fmovem.l of several control registers reverses FPCR and FPIAR), so
 * under emulation the wrong register would come back. Register-direct moves
 * are exact everywhere and cost the same on a 68882.
 */
    /* With the other functions every cycle runs (src/lib/hot.hpp). */
    .section .text.hot.chm_port_switch,"ax",@progbits
    .globl  chm_port_switch
    .type   chm_port_switch, @function
    .p2align 2
chm_port_switch:
    .cfi_startproc
    move.l  4(%sp), %a0
    move.l  8(%sp), %a1
    movem.l %d2-%d7/%a2-%a6, -(%sp)
    fmovem.x %fp2-%fp7, -(%sp)
    fmove.l %fpcr, %d0
    move.l  %d0, -(%sp)
    move.l  %sp, (%a0)
    move.l  %a1, %sp
    move.l  (%sp)+, %d0
    fmove.l %d0, %fpcr
    fmovem.x (%sp)+, %fp2-%fp7
    movem.l (%sp)+, %d2-%d7/%a2-%a6
    rts
    .cfi_endproc
    .size   chm_port_switch, .-chm_port_switch

/* First instruction of every new context: context_init leaves entry in a2,
 * its argument in d2, a6 = 0 (the end of the frame-pointer chain) and sp
 * 4-byte aligned. Pushing the argument keeps it aligned; jsr then pushes the
 * return address, as at any call. */
    .globl  chm_port_context_start
    .type   chm_port_context_start, @function
    .p2align 2
chm_port_context_start:
    .cfi_startproc
    .cfi_undefined %pc
    move.l  %d2, -(%sp)
    jsr     (%a2)
    illegal                         /* entry returned: the contract forbids it */
    .cfi_endproc
    .size   chm_port_context_start, .-chm_port_context_start

    .section .note.GNU-stack,"",@progbits
