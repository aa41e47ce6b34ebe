// Where a task may be preempted: an allow-list of code ranges (the main
// executable and loaded control programs). Everything else (libc, the
// dynamic linker, other shared objects) holds locks or state a green thread
// must not be switched out of, so a preemption there is deferred.
#include "port.hpp"

#include <cerrno>
#include <elf.h>
#include <link.h>

// Hidden: the trampolines reach it PC-relative, also inside libchimera.so.
extern "C" {
__attribute__((visibility("hidden"))) chm::port::PreemptHook chm_port_preempt_hook = nullptr;
__attribute__((visibility("hidden"))) chm::port::PreemptFloorHook chm_port_preempt_floor_hook = nullptr;
}

namespace chm::port {

namespace {

struct Range {
    std::uintptr_t lo, hi;
};
constexpr int kMaxRanges = 64;
Range g_ranges[kMaxRanges];
volatile int g_count = 0;
bool g_defaults_added = false;

int add_main_program(dl_phdr_info* info, std::size_t, void*) {
    // The first object dl_iterate_phdr reports is the main program.
    for (int i = 0; i < info->dlpi_phnum; ++i) {
        const auto& ph = info->dlpi_phdr[i];
        if (ph.p_type == PT_LOAD && (ph.p_flags & PF_X)) {
            const std::uintptr_t lo = info->dlpi_addr + ph.p_vaddr;
            preemptible_range_add(lo, lo + ph.p_memsz);
        }
    }
    return 1;  // stop after the first object
}

// The executable segments of the object holding `want`: added, removed or
// counted.
struct ObjectWalk {
    std::uintptr_t want;
    enum { kAdd, kRemove } op;
    int ranges = 0;
    bool found = false;
};

int walk_object(dl_phdr_info* info, std::size_t, void* arg) {
    auto* w = static_cast<ObjectWalk*>(arg);
    bool holds = false;
    for (int i = 0; i < info->dlpi_phnum && !holds; ++i) {
        const auto& ph = info->dlpi_phdr[i];
        const std::uintptr_t lo = info->dlpi_addr + ph.p_vaddr;
        holds = ph.p_type == PT_LOAD && w->want >= lo && w->want < lo + ph.p_memsz;
    }
    if (!holds) return 0;
    w->found = true;
    for (int i = 0; i < info->dlpi_phnum; ++i) {
        const auto& ph = info->dlpi_phdr[i];
        if (ph.p_type != PT_LOAD || !(ph.p_flags & PF_X)) continue;
        const std::uintptr_t lo = info->dlpi_addr + ph.p_vaddr;
        if (w->op == ObjectWalk::kAdd) {
            if (preemptible_range_add(lo, lo + ph.p_memsz) == 0) ++w->ranges;
        } else {
            preemptible_range_remove(lo, lo + ph.p_memsz);
            ++w->ranges;
        }
    }
    return 1;
}

void add_defaults() {
    if (g_defaults_added) return;
    g_defaults_added = true;
    dl_iterate_phdr(add_main_program, nullptr);
    // The kernel's own code when it is libchimera.so rather than part of
    // the executable: kernel calls made outside the mask (a busy
    // chm_time_consume, a parked UNIX call) stay preemptible like the
    // program that made them.
    if (!preemptible_pc_from_signal(reinterpret_cast<std::uintptr_t>(&add_defaults)))
        preemptible_object_add(reinterpret_cast<const void*>(&add_defaults));
}

}  // namespace

int preemptible_range_add(std::uintptr_t lo, std::uintptr_t hi) {
    if (lo >= hi) return -EINVAL;
    const int n = g_count;
    if (n >= kMaxRanges) return -ENOSPC;
    g_ranges[n] = Range{lo, hi};
    __atomic_signal_fence(__ATOMIC_SEQ_CST);
    g_count = n + 1;  // publish after the entry is complete
    return 0;
}

void preemptible_range_remove(std::uintptr_t lo, std::uintptr_t hi) {
    const int n = g_count;
    for (int i = 0; i < n; ++i) {
        if (g_ranges[i].lo == lo && g_ranges[i].hi == hi) {
            // Called with the mask held: the handler cannot observe the
            // half-moved table.
            g_ranges[i] = g_ranges[n - 1];
            g_count = n - 1;
            return;
        }
    }
}

int preemptible_range_exclude(std::uintptr_t lo, std::uintptr_t hi) {
    if (lo >= hi) return -EINVAL;
    const int n = g_count;
    for (int i = 0; i < n; ++i) {
        const Range r = g_ranges[i];
        if (hi <= r.lo || lo >= r.hi) continue;
        // Mask held by the caller: the handler never sees the table half-done.
        g_ranges[i] = g_ranges[g_count - 1];
        g_count = g_count - 1;
        if (r.lo < lo) preemptible_range_add(r.lo, lo);
        if (hi < r.hi) preemptible_range_add(hi, r.hi);
        return preemptible_range_exclude(lo, hi);  // other ranges may overlap too
    }
    return 0;
}

bool preemptible_pc_from_signal(std::uintptr_t pc) {
    const int n = g_count;
    for (int i = 0; i < n; ++i)
        if (pc >= g_ranges[i].lo && pc < g_ranges[i].hi) return true;
    return false;
}

int preemptible_object_add(const void* addr) {
    ObjectWalk w{reinterpret_cast<std::uintptr_t>(addr), ObjectWalk::kAdd};
    dl_iterate_phdr(walk_object, &w);
    return w.found ? w.ranges : -ENOENT;
}

void preemptible_object_remove(const void* addr) {
    ObjectWalk w{reinterpret_cast<std::uintptr_t>(addr), ObjectWalk::kRemove};
    dl_iterate_phdr(walk_object, &w);
}

// Called from timer_init(), outside any handler.
void preemptible_ranges_init() { add_defaults(); }

}  // namespace chm::port
