/* aarch64 context switch (AAPCS64). Saves what a callee must preserve:
 * x19-x28, the frame pointer x29, the link register x30, the low 64 bits of
 * v8-v15 (d8-d15; the upper halves are caller-saved) and the FPCR (rounding
 * mode, flush-to-zero, default NaN). FPSR holds only sticky status flags and
 * is not part of a context. Everything else is caller-saved, so the compiler
 * has already spilled it around the call.
 *
 *   void chm_port_switch(void **save_sp, void *load_sp)   x0, x1
 *
 * Frame on the suspended stack, 176 bytes (a multiple of 16, so sp stays
 * aligned), low to high:
 *   x19 x20 x21 x22 x23 x24 x25 x26 x27 x28 x29 x30 d8 .. d15 fpcr pad
 * Resuming pops it and returns through the saved x30.
 */
    /* With the other functions every cycle runs (src/lib/hot.hpp). */
    .section .text.hot.chm_port_switch,"ax",%progbits
    .globl  chm_port_switch
    .type   chm_port_switch, %function
    .p2align 4
chm_port_switch:
    .cfi_startproc
    sub     sp, sp, #176
    stp     x19, x20, [sp, #0]
    stp     x21, x22, [sp, #16]
    stp     x23, x24, [sp, #32]
    stp     x25, x26, [sp, #48]
    stp     x27, x28, [sp, #64]
    stp     x29, x30, [sp, #80]
    stp     d8, d9, [sp, #96]
    stp     d10, d11, [sp, #112]
    stp     d12, d13, [sp, #128]
    stp     d14, d15, [sp, #144]
    mrs     x9, fpcr
    str     x9, [sp, #160]
    mov     x10, sp
    str     x10, [x0]
    mov     sp, x1
    /* Writing FPCR serialises the pipeline on many cores: skip it when the
     * incoming context uses the same settings (the common case). */
    ldr     x10, [sp, #160]
    cmp     x9, x10
    b.eq    1f
    msr     fpcr, x10
1:
    ldp     x19, x20, [sp, #0]
    ldp     x21, x22, [sp, #16]
    ldp     x23, x24, [sp, #32]
    ldp     x25, x26, [sp, #48]
    ldp     x27, x28, [sp, #64]
    ldp     x29, x30, [sp, #80]
    ldp     d8, d9, [sp, #96]
    ldp     d10, d11, [sp, #112]
    ldp     d12, d13, [sp, #128]
    ldp     d14, d15, [sp, #144]
    add     sp, sp, #176
    ret
    .cfi_endproc
    .size   chm_port_switch, .-chm_port_switch

/* First instruction of every new context: context_init leaves entry in x19,
 * its argument in x20, x29 = 0 (the end of the frame-pointer chain) and sp
 * 16-byte aligned, as AAPCS64 wants at a call. */
    .globl  chm_port_context_start
    .type   chm_port_context_start, %function
    .p2align 4
chm_port_context_start:
    .cfi_startproc
    .cfi_undefined x30
    mov     x0, x20
    mov     x30, xzr
    blr     x19
    brk     #0x3c                   /* entry returned: the contract forbids it */
    .cfi_endproc
    .size   chm_port_context_start, .-chm_port_context_start

    .section .note.GNU-stack,"",%progbits
