/* Port conformance helpers for aarch64 (see tests/port/regs_helpers.hpp).
 * The callee-saved set under test: x19-x29, d8-d15 and the FPCR. */
    .text

/* int chm_test_switch_check(void **save_sp, void *load_sp, uint64_t seed)
 *                           x0               x1             x2
 * Frame (192 bytes): [0] x29 x30, [16] x19-x28, [96] d8-d15, [160] fpcr,
 * [168] seed. x19-x29 get seed+1 .. seed+11, d8-d15 the bit patterns
 * seed+21 .. seed+28, FPCR round toward zero (RMode 0b11). */
    .globl  chm_test_switch_check
    .type   chm_test_switch_check, %function
    .p2align 2
chm_test_switch_check:
    stp     x29, x30, [sp, #-192]!
    stp     x19, x20, [sp, #16]
    stp     x21, x22, [sp, #32]
    stp     x23, x24, [sp, #48]
    stp     x25, x26, [sp, #64]
    stp     x27, x28, [sp, #80]
    stp     d8, d9, [sp, #96]
    stp     d10, d11, [sp, #112]
    stp     d12, d13, [sp, #128]
    stp     d14, d15, [sp, #144]
    mrs     x9, fpcr
    str     x9, [sp, #160]
    str     x2, [sp, #168]
    add     x19, x2, #1
    add     x20, x2, #2
    add     x21, x2, #3
    add     x22, x2, #4
    add     x23, x2, #5
    add     x24, x2, #6
    add     x25, x2, #7
    add     x26, x2, #8
    add     x27, x2, #9
    add     x28, x2, #10
    add     x29, x2, #11
    add     x9, x2, #21
    fmov    d8, x9
    add     x9, x2, #22
    fmov    d9, x9
    add     x9, x2, #23
    fmov    d10, x9
    add     x9, x2, #24
    fmov    d11, x9
    add     x9, x2, #25
    fmov    d12, x9
    add     x9, x2, #26
    fmov    d13, x9
    add     x9, x2, #27
    fmov    d14, x9
    add     x9, x2, #28
    fmov    d15, x9
    mov     x9, #0x00c00000
    msr     fpcr, x9
    bl      chm_port_switch
    ldr     x2, [sp, #168]

    .macro  CHECK_X n, reg, add
    mov     w0, #\n
    add     x9, x2, #\add
    cmp     \reg, x9
    b.ne    9f
    .endm
    .macro  CHECK_D n, reg, add
    mov     w0, #\n
    add     x9, x2, #\add
    fmov    x10, \reg
    cmp     x10, x9
    b.ne    9f
    .endm
    CHECK_X 1, x19, 1
    CHECK_X 2, x20, 2
    CHECK_X 3, x21, 3
    CHECK_X 4, x22, 4
    CHECK_X 5, x23, 5
    CHECK_X 6, x24, 6
    CHECK_X 7, x25, 7
    CHECK_X 8, x26, 8
    CHECK_X 9, x27, 9
    CHECK_X 10, x28, 10
    CHECK_X 11, x29, 11
    CHECK_D 12, d8, 21
    CHECK_D 13, d9, 22
    CHECK_D 14, d10, 23
    CHECK_D 15, d11, 24
    CHECK_D 16, d12, 25
    CHECK_D 17, d13, 26
    CHECK_D 18, d14, 27
    CHECK_D 19, d15, 28
    mov     w0, #20
    mrs     x10, fpcr
    mov     x9, #0x00c00000
    cmp     x10, x9
    b.ne    9f
    mov     w0, #0
9:
    ldr     x9, [sp, #160]
    msr     fpcr, x9
    ldp     x19, x20, [sp, #16]
    ldp     x21, x22, [sp, #32]
    ldp     x23, x24, [sp, #48]
    ldp     x25, x26, [sp, #64]
    ldp     x27, x28, [sp, #80]
    ldp     d8, d9, [sp, #96]
    ldp     d10, d11, [sp, #112]
    ldp     d12, d13, [sp, #128]
    ldp     d14, d15, [sp, #144]
    ldp     x29, x30, [sp], #192
    ret
    .size   chm_test_switch_check, .-chm_test_switch_check

/* void chm_test_clobber_entry(struct { void **save; void **back; } *arg) */
    .globl  chm_test_clobber_entry
    .type   chm_test_clobber_entry, %function
    .p2align 2
chm_test_clobber_entry:
    sub     sp, sp, #16
    str     x0, [sp]
1:
    mov     x19, #-1
    ldr     x20, =0x5a5a5a5a5a5a5a5a
    ldr     x21, =0x1111111111111111
    ldr     x22, =0x2222222222222222
    ldr     x23, =0x3333333333333333
    ldr     x24, =0x4444444444444444
    ldr     x25, =0x5555555555555555
    ldr     x26, =0x6666666666666666
    ldr     x27, =0x7777777777777777
    ldr     x28, =0x8888888888888888
    ldr     x29, =0x9999999999999999
    fmov    d8, x19
    fmov    d9, x20
    fmov    d10, x21
    fmov    d11, x22
    fmov    d12, x23
    fmov    d13, x24
    fmov    d14, x25
    fmov    d15, x26
    mov     x9, #0x00400000         /* round toward plus infinity */
    msr     fpcr, x9
    ldr     x9, [sp]
    ldr     x0, [x9]
    ldr     x1, [x9, #8]
    ldr     x1, [x1]
    bl      chm_port_switch
    b       1b
    .ltorg
    .size   chm_test_clobber_entry, .-chm_test_clobber_entry

/* void chm_test_sp_probe_entry(struct { uintptr_t sp; void **save; void **back; } *p) */
    .globl  chm_test_sp_probe_entry
    .type   chm_test_sp_probe_entry, %function
    .p2align 2
chm_test_sp_probe_entry:
    mov     x9, sp
    str     x9, [x0]
    ldr     x1, [x0, #16]
    ldr     x1, [x1]
    ldr     x0, [x0, #8]
    bl      chm_port_switch
    brk     #0x3c
    .size   chm_test_sp_probe_entry, .-chm_test_sp_probe_entry

/* Preemption conformance (tests/port/test_port_preempt.cpp):
 *   void chm_test_preempt_spin(uint64_t iterations, uint64_t *out)
 * Loads chm_test_preempt_patterns into x0-x30 (not sp), into both halves of
 * v0-v31, FPCR and FPSR, sets NZCV to N C V, then counts x16 down from
 * `iterations` with sub/cbnz (no flag, no other register touched; x16 is the
 * counter, so its pattern slot holds the 0 it ends at), then stores
 * everything into out: out[0..30] = x0-x30, out[31 + 2i] / out[32 + 2i] =
 * low / high half of v_i, out[95] = FPCR, out[96] = FPSR, out[97] = NZCV.
 * Callee-saved registers and the FPCR are restored before returning. */
    .section .rodata
    .p2align 4
    .globl  chm_test_preempt_patterns
    .type   chm_test_preempt_patterns, %object
chm_test_preempt_patterns:
    .quad 0x11010101c1feef01, 0x22020202c2fdec02, 0x33030303c3fced03
    .quad 0x44040404c4fbea04, 0x55050505c5faeb05, 0x66060606c6f9e806
    .quad 0x77070707c7f8e907, 0x88080808c8f7e608, 0x99090909c9f6e709
    .quad 0xaa0a0a0acaf5e40a, 0xbb0b0b0bcbf4e50b, 0xcc0c0c0cccf3e20c
    .quad 0xdd0d0d0dcdf2e30d, 0xee0e0e0ecef1e00e, 0xff0f0f0fcff0e10f
    .quad 0x20101010d0effe10, 0x0000000000000000, 0x42121212d2edfc12
    .quad 0x53131313d3ecfd13, 0x64141414d4ebfa14, 0x75151515d5eafb15
    .quad 0x86161616d6e9f816, 0x97171717d7e8f917, 0xa8181818d8e7f618
    .quad 0xb9191919d9e6f719, 0xca1a1a1adae5f41a, 0xdb1b1b1bdbe4f51b
    .quad 0xec1c1c1cdce3f21c, 0xfd1d1d1ddde2f31d, 0x0e1e1e1edee1f01e
    .quad 0x2f1f1f1fdfe0f11f, 0x5b58030405065d52, 0xf0e1d0c1b0a19081
    .quad 0x585e06080a0c544a, 0xf0e2d0c2b0a29082, 0x595c090c0f124f42
    .quad 0xf0e3d0c3b0a39083, 0x5e520c101418467a, 0xf0e4d0c4b0a49084
    .quad 0x5f500f14191e7972, 0xf0e5d0c5b0a59085, 0x5c5612181e24706a
    .quad 0xf0e6d0c6b0a69086, 0x5d54151c232a6b62, 0xf0e7d0c7b0a79087
    .quad 0x524a18202830621a, 0xf0e8d0c8b0a89088, 0x53481b242d366512
    .quad 0xf0e9d0c9b0a99089, 0x504e1e28323c1c0a, 0xf0ead0cab0aa908a
    .quad 0x514c212c37421702, 0xf0ebd0cbb0ab908b, 0x564224303c480e3a
    .quad 0xf0ecd0ccb0ac908c, 0x57402734414e0132, 0xf0edd0cdb0ad908d
    .quad 0x54462a384654382a, 0xf0eed0ceb0ae908e, 0x55442d3c4b5a3322
    .quad 0xf0efd0cfb0af908f, 0x4a7a304050602ada, 0xf0f0d0d0b0b09090
    .quad 0x4b78334455662dd2, 0xf0f1d0d1b0b19091, 0x487e36485a6c24ca
    .quad 0xf0f2d0d2b0b29092, 0x497c394c5f72dfc2, 0xf0f3d0d3b0b39093
    .quad 0x4e723c506478d6fa, 0xf0f4d0d4b0b49094, 0x4f703f54697ec9f2
    .quad 0xf0f5d0d5b0b59095, 0x4c7642586e84c0ea, 0xf0f6d0d6b0b69096
    .quad 0x4d74455c738afbe2, 0xf0f7d0d7b0b79097, 0x426a48607890f29a
    .quad 0xf0f8d0d8b0b89098, 0x43684b647d96f592, 0xf0f9d0d9b0b99099
    .quad 0x406e4e68829cec8a, 0xf0fad0dab0ba909a, 0x416c516c87a2e782
    .quad 0xf0fbd0dbb0bb909b, 0x466254708ca89eba, 0xf0fcd0dcb0bc909c
    .quad 0x4760577491ae91b2, 0xf0fdd0ddb0bd909d, 0x44665a7896b488aa
    .quad 0xf0fed0deb0be909e, 0x45645d7c9bba83a2, 0xf0ffd0dfb0bf909f
    .quad 0x7a1a6080a0c0bb5a, 0xf0c0d0e0b08090a0, 0x0000000003c00000
    .quad 0x000000000800009f
    .size   chm_test_preempt_patterns, .-chm_test_preempt_patterns

    .text
    .globl  chm_test_preempt_spin
    .type   chm_test_preempt_spin, %function
    .p2align 2
chm_test_preempt_spin:
    stp     x29, x30, [sp, #-176]!
    stp     x19, x20, [sp, #16]
    stp     x21, x22, [sp, #32]
    stp     x23, x24, [sp, #48]
    stp     x25, x26, [sp, #64]
    stp     x27, x28, [sp, #80]
    stp     d8, d9, [sp, #96]
    stp     d10, d11, [sp, #112]
    stp     d12, d13, [sp, #128]
    stp     d14, d15, [sp, #144]
    mrs     x9, fpcr
    str     x9, [sp, #160]
    str     x1, [sp, #168]          /* out */
    mov     x16, x0                 /* the counter */
    adrp    x17, chm_test_preempt_patterns
    add     x17, x17, :lo12:chm_test_preempt_patterns
    add     x15, x17, #248          /* v0 low half: slot 31 */
    ldr     q0, [x15, #0]
    ldr     q1, [x15, #16]
    ldr     q2, [x15, #32]
    ldr     q3, [x15, #48]
    ldr     q4, [x15, #64]
    ldr     q5, [x15, #80]
    ldr     q6, [x15, #96]
    ldr     q7, [x15, #112]
    ldr     q8, [x15, #128]
    ldr     q9, [x15, #144]
    ldr     q10, [x15, #160]
    ldr     q11, [x15, #176]
    ldr     q12, [x15, #192]
    ldr     q13, [x15, #208]
    ldr     q14, [x15, #224]
    ldr     q15, [x15, #240]
    ldr     q16, [x15, #256]
    ldr     q17, [x15, #272]
    ldr     q18, [x15, #288]
    ldr     q19, [x15, #304]
    ldr     q20, [x15, #320]
    ldr     q21, [x15, #336]
    ldr     q22, [x15, #352]
    ldr     q23, [x15, #368]
    ldr     q24, [x15, #384]
    ldr     q25, [x15, #400]
    ldr     q26, [x15, #416]
    ldr     q27, [x15, #432]
    ldr     q28, [x15, #448]
    ldr     q29, [x15, #464]
    ldr     q30, [x15, #480]
    ldr     q31, [x15, #496]
    ldr     x9, [x17, #760]
    msr     fpcr, x9
    ldr     x9, [x17, #768]
    msr     fpsr, x9
    mov     x9, #0xb0000000         /* N, C, V */
    msr     nzcv, x9
    ldp     x0, x1, [x17, #0]
    ldp     x2, x3, [x17, #16]
    ldp     x4, x5, [x17, #32]
    ldp     x6, x7, [x17, #48]
    ldp     x8, x9, [x17, #64]
    ldp     x10, x11, [x17, #80]
    ldp     x12, x13, [x17, #96]
    ldp     x14, x15, [x17, #112]
    ldr     x18, [x17, #144]
    ldp     x19, x20, [x17, #152]
    ldp     x21, x22, [x17, #168]
    ldp     x23, x24, [x17, #184]
    ldp     x25, x26, [x17, #200]
    ldp     x27, x28, [x17, #216]
    ldp     x29, x30, [x17, #232]
    ldr     x17, [x17, #136]        /* the base goes last */
3:  sub     x16, x16, #1
    cbnz    x16, 3b
    str     x0, [sp, #-16]!
    ldr     x0, [sp, #184]          /* out (168 + 16) */
    stp     x1, x2, [x0, #8]
    stp     x3, x4, [x0, #24]
    stp     x5, x6, [x0, #40]
    stp     x7, x8, [x0, #56]
    stp     x9, x10, [x0, #72]
    stp     x11, x12, [x0, #88]
    stp     x13, x14, [x0, #104]
    stp     x15, x16, [x0, #120]
    stp     x17, x18, [x0, #136]
    stp     x19, x20, [x0, #152]
    stp     x21, x22, [x0, #168]
    stp     x23, x24, [x0, #184]
    stp     x25, x26, [x0, #200]
    stp     x27, x28, [x0, #216]
    stp     x29, x30, [x0, #232]
    ldr     x9, [sp]
    str     x9, [x0]
    add     x10, x0, #248
    str     q0, [x10, #0]
    str     q1, [x10, #16]
    str     q2, [x10, #32]
    str     q3, [x10, #48]
    str     q4, [x10, #64]
    str     q5, [x10, #80]
    str     q6, [x10, #96]
    str     q7, [x10, #112]
    str     q8, [x10, #128]
    str     q9, [x10, #144]
    str     q10, [x10, #160]
    str     q11, [x10, #176]
    str     q12, [x10, #192]
    str     q13, [x10, #208]
    str     q14, [x10, #224]
    str     q15, [x10, #240]
    str     q16, [x10, #256]
    str     q17, [x10, #272]
    str     q18, [x10, #288]
    str     q19, [x10, #304]
    str     q20, [x10, #320]
    str     q21, [x10, #336]
    str     q22, [x10, #352]
    str     q23, [x10, #368]
    str     q24, [x10, #384]
    str     q25, [x10, #400]
    str     q26, [x10, #416]
    str     q27, [x10, #432]
    str     q28, [x10, #448]
    str     q29, [x10, #464]
    str     q30, [x10, #480]
    str     q31, [x10, #496]
    mrs     x9, fpcr
    str     x9, [x0, #760]
    mrs     x9, fpsr
    str     x9, [x0, #768]
    mrs     x9, nzcv
    str     x9, [x0, #776]
    add     sp, sp, #16
    msr     fpsr, xzr               /* do not leak the sticky flags */
    ldr     x9, [sp, #160]
    msr     fpcr, x9
    ldp     x19, x20, [sp, #16]
    ldp     x21, x22, [sp, #32]
    ldp     x23, x24, [sp, #48]
    ldp     x25, x26, [sp, #64]
    ldp     x27, x28, [sp, #80]
    ldp     d8, d9, [sp, #96]
    ldp     d10, d11, [sp, #112]
    ldp     d12, d13, [sp, #128]
    ldp     d14, d15, [sp, #144]
    ldp     x29, x30, [sp], #176
    ret
    .size   chm_test_preempt_spin, .-chm_test_preempt_spin

    .section .note.GNU-stack,"",%progbits
