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

/* Preemption conformance (tests/port/test_port_preempt.cpp):
 *   void chm_test_preempt_spin(uint64_t iterations, uint64_t *out)
 * Loads chm_test_preempt_patterns into d0-d7, a0-a6 (not sp), fp0-fp7 (the
 * full 80-bit values), FPCR and FPSR, sets the CCR to X N V C, then spins
 * with two nested dbra loops (dbra changes no flag): d0 counts 65536 inner
 * iterations, d1 about iterations / 65536 outer ones; both end with their
 * low words at 0xffff, which is what their pattern slots hold. Then stores
 * everything into out, each value in the low bits of a 64-bit slot:
 * out[0..7] = d0-d7, out[8..14] = a0-a6, out[15 + 2i] = sign and exponent
 * of fp_i (shifted left 16, as in the 96-bit memory image), out[16 + 2i] =
 * its mantissa, out[31] = FPCR, out[32] = FPSR, out[33] = CCR. FPIAR is left
 * out: a 68881/2 rewrites it at every FP instruction and qemu does not
 * keep it.
 * The table sits in .text so the code reaches it PC-relative within 16 bits;
 * fp_i's 96-bit image is the 12 bytes at out/table slot 15 + 2i, offset 4. */
    .text
    .globl  chm_test_preempt_spin
    .type   chm_test_preempt_spin, @function
    .p2align 2
chm_test_preempt_spin:
    movem.l %d2-%d7/%a2-%a6, -(%sp)
    fmovem.x %fp2-%fp7, -(%sp)
    fmove.l %fpcr, %d0
    move.l  %d0, -(%sp)
    /* 120 bytes saved: iterations (low word) at 128(sp), out at 132(sp) */
    move.l  128(%sp), %d0
    clr.w   %d0
    swap    %d0                     /* iterations / 65536 */
    subq.w  #1, %d0
    jbcc    1f
    moveq   #0, %d0
1:  move.w  %d0, -(%sp)             /* outer count, popped into d1.w below */
    lea     chm_test_preempt_patterns(%pc), %a0
    fmove.x 124(%a0), %fp0
    fmove.x 140(%a0), %fp1
    fmove.x 156(%a0), %fp2
    fmove.x 172(%a0), %fp3
    fmove.x 188(%a0), %fp4
    fmove.x 204(%a0), %fp5
    fmove.x 220(%a0), %fp6
    fmove.x 236(%a0), %fp7
    move.l  252(%a0), %d0
    fmove.l %d0, %fpcr
    move.l  260(%a0), %d0
    fmove.l %d0, %fpsr
    move.l  4(%a0), %d0
    move.l  12(%a0), %d1
    move.w  (%sp)+, %d1
    move.l  20(%a0), %d2
    move.l  28(%a0), %d3
    move.l  36(%a0), %d4
    move.l  44(%a0), %d5
    move.l  52(%a0), %d6
    move.l  60(%a0), %d7
    movea.l 76(%a0), %a1
    movea.l 84(%a0), %a2
    movea.l 92(%a0), %a3
    movea.l 100(%a0), %a4
    movea.l 108(%a0), %a5
    movea.l 116(%a0), %a6
    move.w  #0x1b, %ccr             /* moves above set flags: set them last */
    movea.l 68(%a0), %a0            /* movea leaves the CCR alone */
2:  dbra    %d0, 2b
    dbra    %d1, 2b
    move.w  %ccr, -(%sp)
    move.l  %a0, -(%sp)
    movea.l 138(%sp), %a0           /* out (132 + 6) */
    clr.l   0(%a0)
    move.l  %d0, 4(%a0)
    clr.l   8(%a0)
    move.l  %d1, 12(%a0)
    clr.l   16(%a0)
    move.l  %d2, 20(%a0)
    clr.l   24(%a0)
    move.l  %d3, 28(%a0)
    clr.l   32(%a0)
    move.l  %d4, 36(%a0)
    clr.l   40(%a0)
    move.l  %d5, 44(%a0)
    clr.l   48(%a0)
    move.l  %d6, 52(%a0)
    clr.l   56(%a0)
    move.l  %d7, 60(%a0)
    clr.l   72(%a0)
    move.l  %a1, 76(%a0)
    clr.l   80(%a0)
    move.l  %a2, 84(%a0)
    clr.l   88(%a0)
    move.l  %a3, 92(%a0)
    clr.l   96(%a0)
    move.l  %a4, 100(%a0)
    clr.l   104(%a0)
    move.l  %a5, 108(%a0)
    clr.l   112(%a0)
    move.l  %a6, 116(%a0)
    fmove.l %fpcr, %d0              /* control first: FP stores may touch FPSR */
    clr.l   248(%a0)
    move.l  %d0, 252(%a0)
    fmove.l %fpsr, %d0
    clr.l   256(%a0)
    move.l  %d0, 260(%a0)
    clr.l   120(%a0)
    fmove.x %fp0, 124(%a0)
    clr.l   136(%a0)
    fmove.x %fp1, 140(%a0)
    clr.l   152(%a0)
    fmove.x %fp2, 156(%a0)
    clr.l   168(%a0)
    fmove.x %fp3, 172(%a0)
    clr.l   184(%a0)
    fmove.x %fp4, 188(%a0)
    clr.l   200(%a0)
    fmove.x %fp5, 204(%a0)
    clr.l   216(%a0)
    fmove.x %fp6, 220(%a0)
    clr.l   232(%a0)
    fmove.x %fp7, 236(%a0)
    move.l  (%sp)+, %d0
    clr.l   64(%a0)
    move.l  %d0, 68(%a0)            /* a0 */
    moveq   #0, %d0
    move.w  (%sp)+, %d0
    clr.l   264(%a0)
    move.l  %d0, 268(%a0)           /* CCR */
    fmove.l #0, %fpsr               /* do not leak the pattern's status */
    move.l  (%sp)+, %d0
    fmove.l %d0, %fpcr
    fmovem.x (%sp)+, %fp2-%fp7
    movem.l (%sp)+, %d2-%d7/%a2-%a6
    rts
    .size   chm_test_preempt_spin, .-chm_test_preempt_spin

    .p2align 2
    .globl  chm_test_preempt_patterns
    .type   chm_test_preempt_patterns, @object
chm_test_preempt_patterns:
    .quad 0x0000000011d1ffff, 0x0000000022e2ffff, 0x0000000033f3ccdd
    .quad 0x000000004484bbaa, 0x000000005595aabb, 0x0000000066a69988
    .quad 0x0000000077b78899, 0x0000000088487766, 0x0000000099596677
    .quad 0x00000000aa6a5544, 0x00000000bb7b4455, 0x00000000cc0c3322
    .quad 0x00000000dd1d2233, 0x00000000ee2e1100, 0x00000000ff3f0011
    .quad 0x000000003fff0000, 0x8369d0369d0369cd, 0x00000000c1100000
    .quad 0x848d159e26af37bc, 0x0000000042210000, 0x85b05b05b05b05ab
    .quad 0x00000000c3320000, 0x86d3a06d3a06d39a, 0x0000000044430000
    .quad 0x87f6e5d4c3b2a189, 0x00000000c5540000, 0x891a2b3c4d5e6f78
    .quad 0x0000000046650000, 0x8a3d70a3d70a3d67, 0x00000000c7760000
    .quad 0x8b60b60b60b60b56, 0x0000000000000090, 0x000000000a2a5aa8
    .size   chm_test_preempt_patterns, .-chm_test_preempt_patterns

    .section .note.GNU-stack,"",@progbits
