/* A control program the console tests load: prints "ready", then reads
 * lines from stdin (the console's terminal, through the host server) and
 * prints "got: LINE" for each, until end of file or "bye". */
#include <stdio.h>
#include <string.h>

int main(int argc, char **argv) {
    const char *me = argc > 1 ? argv[1] : "reader";
    printf("%s ready\n", me);
    char line[256];
    while (fgets(line, sizeof line, stdin)) {
        line[strcspn(line, "\n")] = 0;
        printf("%s got: %s\n", me, line);
        if (!strcmp(line, "bye")) break;
    }
    printf("%s done\n", me);
    return 0;
}
