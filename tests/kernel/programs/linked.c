/* A control program built the way the loader refuses: linked against
 * libchimera (cc -shared -fPIC linked.c -lchimera). It calls into the
 * library, so the link keeps libchimera among the libraries it needs. */
#include <chimera/chimera.h>

int main(int argc, char** argv) {
    (void)argv;
    return argc + (int)(chm_time_now() & 1);
}
