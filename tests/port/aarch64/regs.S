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

    .section .note.GNU-stack,"",%progbits
