/* The bench's module (bench/ipc/servo_rows.cpp): an empty cycle with one
 * input ("in") and one output (OUT, a build option), so a cycle costs the
 * framework's work alone. Its main() (loaded as a program) spawns "bare",
 * a periodic task at PERIOD_NS that does nothing: the peer of a module's
 * cycle, on the same RTPU. */
#include <chimera/module.h>
#include <chimera/task.h>

static const char* const inputs[] = {"in"};
static const char* const outputs[] = {OUT};
static int ok(chm_module_t* m) { (void)m; return 0; }

const chm_module_desc_t chm_module = {
    .abi = CHM_MODULE_ABI, .name = "empty",
    .inputs = inputs, .n_inputs = 1, .outputs = outputs, .n_outputs = 1,
    .init = ok, .on = ok, .cycle = ok, .off = ok, .kill = ok,
};

static void bare(void* arg) {
    (void)arg;
    for (;;) chm_task_wait_period();
}

int main(int argc, char** argv) {
    (void)argc;
    (void)argv;
    chm_task_attr_t a;
    chm_task_attr_init(&a);
    a.name = "bare";
    a.period_ns = 1000000;
    a.priority = 5;
    chm_tid_t t;
    return chm_task_spawn(&t, bare, 0, &a);
}
