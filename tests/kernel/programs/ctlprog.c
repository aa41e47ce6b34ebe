/* A control program as a user writes one: plain C, an ordinary main. The
 * test loads it as a shared object. It spins argv[1] million times in its
 * own code (no call out, so only a preemption inside this object can let
 * another task run), then returns argc * 100 + strlen(argv[2]). */
#include <chimera/chimera.h>
#include <stdlib.h>
#include <string.h>

int main(int argc, char** argv) {
    if (argc < 3 || argv[argc] != NULL) return -1;
    const unsigned long n = (unsigned long)atoi(argv[1]) * 1000000ul;
    volatile unsigned long spins = 0;
    while (spins < n) spins = spins + 1;
    return argc * 100 + (int)strlen(argv[2]);
}
