// The cheap interrupt mask: a nesting count the timer handler honours. Its
// slow path runs a tick that arrived while the mask was held.
#include "port.hpp"

namespace chm::port {

IrqState g_irq{0, 0};

namespace {
PendingHook g_pending_hook = nullptr;
}

void irq_set_pending_hook(PendingHook hook) { g_pending_hook = hook; }

void irq_take_pending() {
    for (;;) {
        // Re-take the mask so the hook runs in a critical section and a tick
        // landing meanwhile is again only recorded.
        g_irq.nest = 1;
        __atomic_signal_fence(__ATOMIC_SEQ_CST);
        while (g_irq.pending) {
            const std::uint32_t why = irq_take_pending_bits();
            __atomic_signal_fence(__ATOMIC_SEQ_CST);
            if (g_pending_hook) g_pending_hook(why);
        }
        __atomic_signal_fence(__ATOMIC_SEQ_CST);
        g_irq.nest = 0;
        __atomic_signal_fence(__ATOMIC_SEQ_CST);
        // A tick recorded between the loop's last test and the store above
        // would otherwise be lost (and the timer left unarmed); one after it
        // is taken by the handler itself, the mask being clear.
        if (!g_irq.pending) return;
    }
}

}  // namespace chm::port
