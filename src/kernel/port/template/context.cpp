// The template port: a documented, empty port/<arch>/context.cpp. It owns
// context_init, which turns a bare stack into a suspended context that the
// first chm_port_switch into it starts by calling entry(arg).
#include "port.hpp"

#include <cstring>

extern "C" void chm_port_context_start();

namespace chm::port {

namespace {

// Mirror of the frame chm_port_switch pops, lowest address first. The
// offsets are load-bearing: keep them in step with switch.S and let the
// compiler check the size.
struct SwitchFrame {
    // callee-saved registers, FP control word(s), return address ...
};

}  // namespace

// Prepare `ctx` so that the first context_switch() into it calls
// entry(arg) on the stack [stack_lo, stack_lo + size).
//
// What it must do:
//  * round the stack top down to kStackAlign (callers may pass any size);
//  * place a SwitchFrame just below it, so that popping the frame leaves the
//    stack pointer where chm_port_context_start needs it: aligned so that
//    its call enters `entry` with (sp + kSpAtEntryBias) % kStackAlign == 0;
//  * store entry and arg in two callee-saved slots of the frame (the switch
//    restores them; context_start reads them), 0 in the frame-pointer slot,
//    the address of chm_port_context_start as the return address, and the
//    ABI's default FP control state (round to nearest, all FP exceptions
//    masked/untrapped -- the value a Linux process starts with) in the FP
//    control slots; any other slot may hold anything (zero it);
//  * set ctx->sp to the frame.
// Pre:  stack_lo is at least 16-byte aligned; size >= kMinStack; the stack
//       is not in use. Task or kernel context.
// Post: ctx->sp points inside the stack; nothing outside
//       [ctx->sp, stack_lo + size) was written. On entry to `entry` the
//       stack is aligned as above, the FP control state is the default
//       whatever the switching context had, and callee-saved registers hold
//       unspecified values.
void context_init(Context* ctx, void* stack_lo, std::size_t size,
                  void (*entry)(void*), void* arg) {
    (void)stack_lo;
    (void)size;
    (void)entry;
    (void)arg;
    ctx->sp = nullptr;
}

}  // namespace chm::port
