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
