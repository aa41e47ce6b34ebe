/* Port conformance helpers for x86-64 (see tests/port/regs_helpers.hpp). */
    .text

/* int chm_test_switch_check(void **save_sp, void *load_sp, uint64_t seed) */
    .globl  chm_test_switch_check
    .type   chm_test_switch_check, @function
chm_test_switch_check:
    pushq   %rbp
    pushq   %rbx
    pushq   %r12
    pushq   %r13
    pushq   %r14
    pushq   %r15
    subq    $24, %rsp
    stmxcsr (%rsp)
    fnstcw  4(%rsp)
    movq    %rdx, 8(%rsp)
    leaq    1(%rdx), %rbx
    leaq    2(%rdx), %rbp
    leaq    3(%rdx), %r12
    leaq    4(%rdx), %r13
    leaq    5(%rdx), %r14
    leaq    6(%rdx), %r15
    movl    $0x7f80, 16(%rsp)       /* round toward zero, all masked */
    ldmxcsr 16(%rsp)
    movw    $0x0c7f, 20(%rsp)       /* x87: round toward zero */
    fldcw   20(%rsp)
    call    chm_port_switch
    movq    8(%rsp), %rdx
    movl    $1, %eax
    leaq    1(%rdx), %rcx
    cmpq    %rcx, %rbx
    jne     1f
    movl    $2, %eax
    leaq    2(%rdx), %rcx
    cmpq    %rcx, %rbp
    jne     1f
    movl    $3, %eax
    leaq    3(%rdx), %rcx
    cmpq    %rcx, %r12
    jne     1f
    movl    $4, %eax
    leaq    4(%rdx), %rcx
    cmpq    %rcx, %r13
    jne     1f
    movl    $5, %eax
    leaq    5(%rdx), %rcx
    cmpq    %rcx, %r14
    jne     1f
    movl    $6, %eax
    leaq    6(%rdx), %rcx
    cmpq    %rcx, %r15
    jne     1f
    movl    $7, %eax
    stmxcsr 16(%rsp)
    movl    16(%rsp), %ecx
    andl    $0xffc0, %ecx            /* ignore sticky status flags */
    cmpl    $0x7f80, %ecx
    jne     1f
    movl    $8, %eax
    fnstcw  20(%rsp)
    movzwl  20(%rsp), %ecx
    cmpl    $0x0c7f, %ecx
    jne     1f
    xorl    %eax, %eax
1:
    ldmxcsr (%rsp)
    fldcw   4(%rsp)
    addq    $24, %rsp
    popq    %r15
    popq    %r14
    popq    %r13
    popq    %r12
    popq    %rbx
    popq    %rbp
    ret
    .size   chm_test_switch_check, .-chm_test_switch_check

/* void chm_test_clobber_entry(struct { void **save; void **back; } *arg) */
    .globl  chm_test_clobber_entry
    .type   chm_test_clobber_entry, @function
chm_test_clobber_entry:
    subq    $8, %rsp
    movq    %rdi, (%rsp)
2:
    movq    $-1, %rbx
    movabsq $0x5a5a5a5a5a5a5a5a, %rbp
    movabsq $0x1111111111111111, %r12
    movabsq $0x2222222222222222, %r13
    movabsq $0x3333333333333333, %r14
    movabsq $0x4444444444444444, %r15
    subq    $8, %rsp
    movl    $0x5f80, (%rsp)          /* round up */
    ldmxcsr (%rsp)
    movw    $0x087f, 4(%rsp)         /* x87: round up */
    fldcw   4(%rsp)
    addq    $8, %rsp
    movq    (%rsp), %rax
    movq    (%rax), %rdi
    movq    8(%rax), %rsi
    movq    (%rsi), %rsi
    call    chm_port_switch
    jmp     2b
    .size   chm_test_clobber_entry, .-chm_test_clobber_entry

/* void chm_test_sp_probe_entry(struct { uintptr_t sp; void **save; void **back; } *p) */
    .globl  chm_test_sp_probe_entry
    .type   chm_test_sp_probe_entry, @function
chm_test_sp_probe_entry:
    movq    %rsp, (%rdi)
    subq    $8, %rsp
    movq    %rdi, %rax
    movq    8(%rax), %rdi
    movq    16(%rax), %rsi
    movq    (%rsi), %rsi
    call    chm_port_switch
    ud2
    .size   chm_test_sp_probe_entry, .-chm_test_sp_probe_entry

    .section .note.GNU-stack,"",@progbits

/* Preemption conformance (tests/port/test_port_preempt.cpp):
 *   void chm_test_preempt_spin(uint64_t iterations, uint64_t *out)
 * Loads chm_test_preempt_patterns into rax..r15 (not rsp) and xmm0-15, sets
 * CF, burns `iterations` decrements of a stack counter (dec keeps CF and
 * touches no register), then stores every register and rflags into out:
 * out[0..14] = rax rbx rcx rdx rsi rdi rbp r8..r15, out[15..30] = xmm0-15
 * (low 64 bits), out[31] = rflags. */
    .section .rodata
    .p2align 3
    .globl  chm_test_preempt_patterns
chm_test_preempt_patterns:
    .quad 0x1010101010101011, 0x2020202020202022, 0x3030303030303033
    .quad 0x4040404040404044, 0x5050505050505055, 0x6060606060606066
    .quad 0x7070707070707077, 0x8080808080808088, 0x9090909090909099
    .quad 0xa0a0a0a0a0a0a0aa, 0xb0b0b0b0b0b0b0bb, 0xc0c0c0c0c0c0c0cc
    .quad 0xd0d0d0d0d0d0d0dd, 0xe0e0e0e0e0e0e0ee, 0xf0f0f0f0f0f0f0ff
    .quad 0x0102030405060708, 0x1112131415161718, 0x2122232425262728
    .quad 0x3132333435363738, 0x4142434445464748, 0x5152535455565758
    .quad 0x6162636465666768, 0x7172737475767778, 0x8182838485868788
    .quad 0x9192939495969798, 0xa1a2a3a4a5a6a7a8, 0xb1b2b3b4b5b6b7b8
    .quad 0xc1c2c3c4c5c6c7c8, 0xd1d2d3d4d5d6d7d8, 0xe1e2e3e4e5e6e7e8
    .quad 0xf1f2f3f4f5f6f7f8
    .text
    .globl  chm_test_preempt_spin
    .type   chm_test_preempt_spin, @function
chm_test_preempt_spin:
    pushq   %rbp
    pushq   %rbx
    pushq   %r12
    pushq   %r13
    pushq   %r14
    pushq   %r15
    pushq   %rsi                    /* out */
    pushq   %rdi                    /* counter */
    leaq    chm_test_preempt_patterns(%rip), %rax
    movq    120(%rax), %xmm0
    movq    128(%rax), %xmm1
    movq    136(%rax), %xmm2
    movq    144(%rax), %xmm3
    movq    152(%rax), %xmm4
    movq    160(%rax), %xmm5
    movq    168(%rax), %xmm6
    movq    176(%rax), %xmm7
    movq    184(%rax), %xmm8
    movq    192(%rax), %xmm9
    movq    200(%rax), %xmm10
    movq    208(%rax), %xmm11
    movq    216(%rax), %xmm12
    movq    224(%rax), %xmm13
    movq    232(%rax), %xmm14
    movq    240(%rax), %xmm15
    movq    8(%rax), %rbx
    movq    16(%rax), %rcx
    movq    24(%rax), %rdx
    movq    32(%rax), %rsi
    movq    40(%rax), %rdi
    movq    48(%rax), %rbp
    movq    56(%rax), %r8
    movq    64(%rax), %r9
    movq    72(%rax), %r10
    movq    80(%rax), %r11
    movq    88(%rax), %r12
    movq    96(%rax), %r13
    movq    104(%rax), %r14
    movq    112(%rax), %r15
    movq    (%rax), %rax
    stc
3:  decq    (%rsp)
    jnz     3b
    pushfq
    pushq   %rax
    movq    24(%rsp), %rax          /* out */
    movq    %rbx, 8(%rax)
    movq    %rcx, 16(%rax)
    movq    %rdx, 24(%rax)
    movq    %rsi, 32(%rax)
    movq    %rdi, 40(%rax)
    movq    %rbp, 48(%rax)
    movq    %r8, 56(%rax)
    movq    %r9, 64(%rax)
    movq    %r10, 72(%rax)
    movq    %r11, 80(%rax)
    movq    %r12, 88(%rax)
    movq    %r13, 96(%rax)
    movq    %r14, 104(%rax)
    movq    %r15, 112(%rax)
    movq    %xmm0, 120(%rax)
    movq    %xmm1, 128(%rax)
    movq    %xmm2, 136(%rax)
    movq    %xmm3, 144(%rax)
    movq    %xmm4, 152(%rax)
    movq    %xmm5, 160(%rax)
    movq    %xmm6, 168(%rax)
    movq    %xmm7, 176(%rax)
    movq    %xmm8, 184(%rax)
    movq    %xmm9, 192(%rax)
    movq    %xmm10, 200(%rax)
    movq    %xmm11, 208(%rax)
    movq    %xmm12, 216(%rax)
    movq    %xmm13, 224(%rax)
    movq    %xmm14, 232(%rax)
    movq    %xmm15, 240(%rax)
    popq    %rcx
    movq    %rcx, (%rax)
    popq    %rcx
    movq    %rcx, 248(%rax)
    addq    $16, %rsp
    popq    %r15
    popq    %r14
    popq    %r13
    popq    %r12
    popq    %rbx
    popq    %rbp
    ret
    .size   chm_test_preempt_spin, .-chm_test_preempt_spin
    .section .note.GNU-stack,"",@progbits
