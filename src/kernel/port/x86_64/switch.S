/* x86-64 context switch (System V ABI). Saves what a callee must preserve:
 * rbx, rbp, r12-r15, the MXCSR and the x87 control word. Everything else is
 * caller-saved, so the compiler has already spilled it around the call.
 *
 *   void chm_port_switch(void **save_sp, void *load_sp)   rdi, rsi
 *
 * Frame on the suspended stack (low to high):
 *   [mxcsr:4][x87cw:2][pad:2] r15 r14 r13 r12 rbx rbp <return address>
 */
/* The body shared by both entries below; only how it resumes differs. */
.macro SWITCH_BODY
    pushq   %rbp
    pushq   %rbx
    pushq   %r12
    pushq   %r13
    pushq   %r14
    pushq   %r15
    subq    $8, %rsp
    stmxcsr (%rsp)
    fnstcw  4(%rsp)
    movq    %rsp, (%rdi)
    movq    %rsp, %rax
    movq    %rsi, %rsp
    /* ldmxcsr and fldcw are slow (they serialise): load only what differs,
     * which on a control task is almost never. */
    movl    (%rsp), %ecx
    cmpl    (%rax), %ecx
    je      1f
    ldmxcsr (%rsp)
1:  movzwl  4(%rsp), %ecx
    cmpw    4(%rax), %cx
    je      2f
    fldcw   4(%rsp)
2:  addq    $8, %rsp
    popq    %r15
    popq    %r14
    popq    %r13
    popq    %r12
    popq    %rbx
    popq    %rbp
.endm

    /* With the other functions every cycle runs (src/lib/hot.hpp). */
    .section .text.hot.chm_port_switch,"ax",@progbits
    .globl  chm_port_switch
    .type   chm_port_switch, @function
    .p2align 4
chm_port_switch:
    .cfi_startproc
    SWITCH_BODY
    /* pop + indirect jump rather than `ret`: for callers that switch from
     * different call sites, the return-stack predictor holds this
     * context's caller, not the incoming one's; the indirect-branch
     * predictor learns the alternation. */
    popq    %r8
    jmp     *%r8
    .cfi_endproc
    .size   chm_port_switch, .-chm_port_switch

/* The kernel's dispatcher switches from one call site only, so the
 * incoming context returns to the very address the return-stack predictor
 * holds. A plain `ret` keeps that stack in step: after the pop + jump
 * above, every later `ret` of the incoming context mispredicts (a yield
 * through the scheduler: 39 -> 22 ns). Same frame as chm_port_switch. */
    .globl  chm_port_switch_same_site
    .type   chm_port_switch_same_site, @function
    .p2align 4
chm_port_switch_same_site:
    .cfi_startproc
    SWITCH_BODY
    ret
    .cfi_endproc
    .size   chm_port_switch_same_site, .-chm_port_switch_same_site

/* The body of both indirect-return entries below: call the function in
 * `fn` (a register), then return to the entry's caller through an
 * indirect jump, its result (rax) untouched. */
.macro CALL_THEN_JUMP_BACK fn
    subq    $8, %rsp
    .cfi_adjust_cfa_offset 8
    call    *\fn
    addq    $8, %rsp
    .cfi_adjust_cfa_offset -8
    popq    %rcx
    .cfi_adjust_cfa_offset -8
    .cfi_register rip, rcx
    jmp     *%rcx
.endm

/* void chm_port_call_indirect_return(void (*fn)(void))
 * Calls fn, then returns to our caller through an indirect jump, not `ret`.
 * For a kernel entry that switches tasks (chm_task_yield tail-calls this):
 * the return address is the incoming task's caller while the return-stack
 * predictor holds the outgoing one's, so a `ret` mispredicts on every
 * switch between tasks that yield from different places; the indirect
 * predictor learns their alternation (as Boost.Context's jump does). */
    .globl  chm_port_call_indirect_return
    .type   chm_port_call_indirect_return, @function
    .p2align 4
chm_port_call_indirect_return:
    .cfi_startproc
    CALL_THEN_JUMP_BACK %rdi
    .cfi_endproc
    .size   chm_port_call_indirect_return, .-chm_port_call_indirect_return

/* int chm_port_call2_indirect_return(int (*fn)(void*, uintptr_t), void* a, uintptr_t b)
 * The same for a kernel entry with two arguments and a result: calls
 * fn(a, b) and returns its result (rax, untouched) through an indirect
 * jump. */
    .globl  chm_port_call2_indirect_return
    .type   chm_port_call2_indirect_return, @function
    .p2align 4
chm_port_call2_indirect_return:
    .cfi_startproc
    movq    %rdi, %rax
    movq    %rsi, %rdi
    movq    %rdx, %rsi
    CALL_THEN_JUMP_BACK %rax
    .cfi_endproc
    .size   chm_port_call2_indirect_return, .-chm_port_call2_indirect_return

/* First instruction of every new context: context_init leaves entry in r12
 * and its argument in r13, and the stack 16-byte aligned here, so the call
 * below enters `entry` with rsp+8 aligned as the ABI wants. */
    .globl  chm_port_context_start
    .type   chm_port_context_start, @function
    .p2align 4
chm_port_context_start:
    .cfi_startproc
    .cfi_undefined rip
    xorl    %ebp, %ebp
    movq    %r13, %rdi
    call    *%r12
    ud2
    .cfi_endproc
    .size   chm_port_context_start, .-chm_port_context_start

    .section .note.GNU-stack,"",@progbits
