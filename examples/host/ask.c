/* A control program that talks with the console: asks for a name on stdin
 * (the console's terminal, when its RTPU has it) and answers. */
#include <stdio.h>
#include <string.h>

int main(int argc, char **argv) {
    const char *who = argc > 1 ? argv[1] : "ask";
    char name[64];
    printf("%s: your name?\n", who);
    if (!fgets(name, sizeof name, stdin)) return 1;
    name[strcspn(name, "\n")] = 0;
    printf("%s: hello, %s\n", who, name);
    return 0;
}
