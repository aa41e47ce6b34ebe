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
    // Re-take the mask so the hook runs in a critical section and a tick
    // landing meanwhile is again only recorded.
    g_irq.nest = 1;
    __atomic_signal_fence(__ATOMIC_SEQ_CST);
    while (g_irq.pending) {
        g_irq.pending = 0;
        __atomic_signal_fence(__ATOMIC_SEQ_CST);
        if (g_pending_hook) g_pending_hook();
    }
    __atomic_signal_fence(__ATOMIC_SEQ_CST);
    g_irq.nest = 0;
    // A tick that lands between the loop test and this store is taken by
    // the handler itself, because the mask is clear again.
}

}  // namespace chm::port
