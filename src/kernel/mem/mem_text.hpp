// Where the allocator's machine code lives. Every function of the allocator
// (TLSF, heap, C API, malloc interposition) is placed in one section,
// chm_mem_text, so the port can tell from a program counter that a task is
// inside the allocator and treat it as it treats the C library: no
// preemption there (heap.hpp: allocator_code_range()).
//
// Why a code range and not only the preemption hooks around the heap lock:
// the C library calls malloc while holding its own locks (a FILE's lock
// while it allocates the stream buffer, for one). A task switched out
// anywhere in malloc, before the lock, after it, or by a tick delivered when
// the hooks unmask, leaves that lock held by a task that is not running, and
// glibc's locks are recursive per OS thread, so the next task on the kernel
// thread walks straight in (observed: torn stdio output under a 50 us
// quantum). So nothing the allocator executes may be preemptible code:
//  * its own functions are in chm_mem_text;
//  * functions defined in headers are inline, hence COMDAT, and GCC cannot
//    mix COMDAT and ordinary functions in one named section, so they are
//    forced inline into their callers (CHM_MEM_INLINE), even at -O0;
//  * the heap uses __atomic builtins, not std::atomic, whose member
//    functions would be out-of-line COMDAT code at -O0;
//  * each source file is compiled without PLT stubs (the pragma at its top),
//    because a statically linked program's stubs lie in its own text;
//    where the compiler ignores that (m68k), the port carves the program's
//    PLT entries out of the preemptible code (port/posix/plt_ranges.cpp);
//  * on aarch64 each is compiled without out-of-line atomics (the second
//    pragma): GCC otherwise calls helpers (__aarch64_cas4_acq, ...) that
//    libgcc links into the program's own text (lost stdio lines in 1 to 3
//    runs in 10 of CLibraryIsSafeUnderPreemption under qemu-aarch64);
//    tests/kernel/mem/alloc_callees_check.py checks every direct branch
//    out of chm_mem_text in each architecture's build;
//  * the heap lock's hooks (core/kernel.cpp: heap_enter, heap_leave) are in
//    the section too, and inline everything they run while the mask is
//    free (out of line, the return of irq_restore_no_switch was preemptible
//    code: lost stdio lines in 4 to 5 runs in 30 under qemu-aarch64);
//  * the C library and the system calls it reaches are not preemptible.
#pragma once

#define CHM_MEM_TEXT __attribute__((section("chm_mem_text")))
#define CHM_MEM_INLINE __attribute__((always_inline))
