/* Port conformance helpers for m68k (see tests/port/regs_helpers.hpp).
 * The callee-saved set under test: d2-d7, a2-a6 (a6 included: the frame
 * pointer is callee-saved too), fp2-fp7 and the FPCR. Arguments arrive on
 * the stack; the 64-bit seed is big-endian, so its low word is the second. */
    .text

/* int chm_test_switch_check(void **save_sp, void *load_sp, uint64_t seed)
 * After saving 120 bytes the arguments sit at 124(sp) save, 128(sp) load,
 * 132(sp) seed high, 136(sp) seed low. d2-d7 and a2-a6 get seed+1 ..
 * seed+11, fp2-fp7 the values seed+21 .. seed+26 (exact in extended
 * precision), FPCR round toward zero (RZ, 0x10). */
    .globl  chm_test_switch_check
    .type   chm_test_switch_check, @function
    .p2align 2
chm_test_switch_check:
    movem.l %d2-%d7/%a2-%a6, -(%sp)
    fmovem.x %fp2-%fp7, -(%sp)
    fmove.l %fpcr, %d0              /* not fmove to -(sp): see switch.S */
    move.l  %d0, -(%sp)
    move.l  136(%sp), %d0
    move.l  %d0, %a0
    lea     1(%a0), %a1
    move.l  %a1, %d2
    lea     2(%a0), %a1
    move.l  %a1, %d3
    lea     3(%a0), %a1
    move.l  %a1, %d4
    lea     4(%a0), %a1
    move.l  %a1, %d5
    lea     5(%a0), %a1
    move.l  %a1, %d6
    lea     6(%a0), %a1
    move.l  %a1, %d7
    lea     21(%a0), %a1
    move.l  %a1, %d0
    fmove.l %d0, %fp2
    addq.l  #1, %d0
    fmove.l %d0, %fp3
    addq.l  #1, %d0
    fmove.l %d0, %fp4
    addq.l  #1, %d0
    fmove.l %d0, %fp5
    addq.l  #1, %d0
    fmove.l %d0, %fp6
    addq.l  #1, %d0
    fmove.l %d0, %fp7
    lea     7(%a0), %a2
    lea     8(%a0), %a3
    lea     9(%a0), %a4
    lea     10(%a0), %a5
    lea     11(%a0), %a6
    fmove.l #0x10, %fpcr
    move.l  128(%sp), -(%sp)        /* load_sp */
    move.l  128(%sp), -(%sp)        /* save_sp (one slot further now) */
    jsr     chm_port_switch
    addq.l  #8, %sp
    move.l  136(%sp), %a0           /* seed */

    .macro  CHECK_R n, reg, add
    moveq   #\n, %d1
    lea     \add(%a0), %a1
    cmp.l   %a1, \reg
    jbne    9f
    .endm
    .macro  CHECK_FP n, reg, add
    moveq   #\n, %d1
    lea     \add(%a0), %a1
    move.l  %a1, %d0
    fcmp.l  %d0, \reg
    fjne    9f
    .endm
    CHECK_R 1, %d2, 1
    CHECK_R 2, %d3, 2
    CHECK_R 3, %d4, 3
    CHECK_R 4, %d5, 4
    CHECK_R 5, %d6, 5
    CHECK_R 6, %d7, 6
    CHECK_R 7, %a2, 7
    CHECK_R 8, %a3, 8
    CHECK_R 9, %a4, 9
    CHECK_R 10, %a5, 10
    CHECK_R 11, %a6, 11
    CHECK_FP 12, %fp2, 21
    CHECK_FP 13, %fp3, 22
    CHECK_FP 14, %fp4, 23
    CHECK_FP 15, %fp5, 24
    CHECK_FP 16, %fp6, 25
    CHECK_FP 17, %fp7, 26
    moveq   #18, %d1
    fmove.l %fpcr, %d0
    cmp.l   #0x10, %d0
    jbne    9f
    moveq   #0, %d1
9:
    move.l  (%sp)+, %d0
    fmove.l %d0, %fpcr
    move.l  %d1, %d0
    fmovem.x (%sp)+, %fp2-%fp7
    movem.l (%sp)+, %d2-%d7/%a2-%a6
    rts
    .size   chm_test_switch_check, .-chm_test_switch_check

/* void chm_test_clobber_entry(struct { void **save; void **back; } *arg)
 * The argument stays at 4(sp) for the life of the context. */
    .globl  chm_test_clobber_entry
    .type   chm_test_clobber_entry, @function
    .p2align 2
chm_test_clobber_entry:
1:
    moveq   #-1, %d2
    move.l  #0x5a5a5a5a, %d3
    move.l  #0x11111111, %d4
    move.l  #0x22222222, %d5
    move.l  #0x33333333, %d6
    move.l  #0x44444444, %d7
    move.l  #0x55555555, %a2
    move.l  #0x66666666, %a3
    move.l  #0x77777777, %a4
    move.l  #0x88888888, %a5
    move.l  #0x99999999, %a6
    fmove.l #-1, %fp2
    fmove.l #-2, %fp3
    fmove.l #-3, %fp4
    fmove.l #-4, %fp5
    fmove.l #-5, %fp6
    fmove.l #-6, %fp7
    fmove.l #0x30, %fpcr            /* round toward plus infinity */
    move.l  4(%sp), %a0
    move.l  4(%a0), %a1             /* back */
    move.l  (%a1), -(%sp)
    move.l  (%a0), -(%sp)           /* save */
    jsr     chm_port_switch
    addq.l  #8, %sp
    jbra    1b
    .size   chm_test_clobber_entry, .-chm_test_clobber_entry

/* void chm_test_sp_probe_entry(struct { uintptr_t sp; void **save; void **back; } *p) */
    .globl  chm_test_sp_probe_entry
    .type   chm_test_sp_probe_entry, @function
    .p2align 2
chm_test_sp_probe_entry:
    move.l  4(%sp), %a0
    move.l  %sp, (%a0)
    move.l  8(%a0), %a1             /* back */
    move.l  (%a1), -(%sp)
    move.l  4(%a0), -(%sp)          /* save */
    jsr     chm_port_switch
    illegal
    .size   chm_test_sp_probe_entry, .-chm_test_sp_probe_entry

    .section .note.GNU-stack,"",@progbits
