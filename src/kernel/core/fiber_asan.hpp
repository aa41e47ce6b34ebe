// AddressSanitizer's view of task stacks. A switch moves the processor onto
// another task's stack behind the sanitizer's back; told with
// __sanitizer_start_switch_fiber / __sanitizer_finish_switch_fiber, it keeps
// each stack's fake frames and bounds apart (and reports a real overflow
// instead of a false one). Everything here is empty in a build without
// AddressSanitizer (meson -Db_sanitize=address,...: make test-asan).
#pragma once

#include <cstddef>

#if defined(__SANITIZE_ADDRESS__)
#define CHM_ASAN_FIBERS 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define CHM_ASAN_FIBERS 1
#endif
#endif

#if CHM_ASAN_FIBERS
#include <pthread.h>
#include <sanitizer/asan_interface.h>
#include <sanitizer/common_interface_defs.h>
#endif

namespace chm::kernel::asan {

#if CHM_ASAN_FIBERS
// The kernel thread's own stack (the idle context's), found at first use.
inline void kernel_stack(const void** lo, std::size_t* size) {
    static thread_local const void* t_lo = nullptr;
    static thread_local std::size_t t_size = 0;
    if (!t_lo) {
        pthread_attr_t a;
        void* addr = nullptr;
        if (pthread_getattr_np(pthread_self(), &a) == 0) {
            (void)pthread_attr_getstack(&a, &addr, &t_size);
            pthread_attr_destroy(&a);
        }
        t_lo = addr;
    }
    *lo = t_lo;
    *size = t_size;
}

// Before the switch onto [lo, lo + size) (null: the kernel thread's stack).
// A context leaving for good (an ended task) passes no save slot, so its
// fake stack is freed.
inline void switch_begin(void** save, const void* lo, std::size_t size) {
    if (!lo) kernel_stack(&lo, &size);
    __sanitizer_start_switch_fiber(save, lo, size);
}
// Back on the saved context (or first thing on a new one: save null).
inline void switch_end(void* save) { __sanitizer_finish_switch_fiber(save, nullptr, nullptr); }
// A stack about to start a new task: the frames of the task that last ran
// on it never returned, so their red zones are still marked.
inline void stack_fresh(void* lo, std::size_t size) { __asan_unpoison_memory_region(lo, size); }
#else
inline void switch_begin(void**, const void*, std::size_t) {}
inline void switch_end(void*) {}
inline void stack_fresh(void*, std::size_t) {}
#endif

}  // namespace chm::kernel::asan
