/* x86-64 preemption trampoline. The timer handler pushed the interrupted
 * rip below the red zone and pointed rip here (x86_64/preempt.cpp). We save
 * everything the interrupted code may have live (all caller-saved integer
 * registers, rflags, the whole x87/SSE/AVX state), call the kernel through
 * chm_port_preempt_hook (callee-saved registers survive the C call by the
 * ABI), restore, and return to the interrupted instruction, releasing the
 * red zone with `ret $128`. */
    .text
    .globl  chm_port_preempt_trampoline
    .type   chm_port_preempt_trampoline, @function
    .p2align 4
chm_port_preempt_trampoline:
    pushfq
    cld                             /* the ABI wants DF clear at a call */
    pushq   %rax
    pushq   %rcx
    pushq   %rdx
    pushq   %rsi
    pushq   %rdi
    pushq   %r8
    pushq   %r9
    pushq   %r10
    pushq   %r11
    pushq   %rbp
    movq    %rsp, %rbp
    andq    $-64, %rsp
    movl    chm_port_xsave_size(%rip), %eax
    testl   %eax, %eax
    jz      1f
    subq    %rax, %rsp
    andq    $-64, %rsp
    /* XRSTOR faults on a non-zero reserved header: clear it first. */
    xorl    %ecx, %ecx
    movq    %rcx, 512(%rsp)
    movq    %rcx, 520(%rsp)
    movq    %rcx, 528(%rsp)
    movq    %rcx, 536(%rsp)
    movq    %rcx, 544(%rsp)
    movq    %rcx, 552(%rsp)
    movq    %rcx, 560(%rsp)
    movq    %rcx, 568(%rsp)
    movl    chm_port_xsave_mask(%rip), %eax
    xorl    %edx, %edx
    xsave64 (%rsp)
    call    *chm_port_preempt_hook(%rip)
    movl    chm_port_xsave_mask(%rip), %eax
    xorl    %edx, %edx
    xrstor64 (%rsp)
    jmp     2f
1:  /* no XSAVE: the legacy 512-byte x87/SSE image */
    subq    $512, %rsp
    fxsave64 (%rsp)
    call    *chm_port_preempt_hook(%rip)
    fxrstor64 (%rsp)
2:
    movq    %rbp, %rsp
    popq    %rbp
    popq    %r11
    popq    %r10
    popq    %r9
    popq    %r8
    popq    %rdi
    popq    %rsi
    popq    %rdx
    popq    %rcx
    popq    %rax
    popfq
    ret     $128
    .size   chm_port_preempt_trampoline, .-chm_port_preempt_trampoline

    .section .note.GNU-stack,"",@progbits
