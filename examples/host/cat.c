/* A control program that prints a host file (beneath the host server's
 * root) through the extended file system and buffered stdio: the read parks
 * only this task; the RTPU's other tasks keep their periods. */
#include <chimera/chimera.h>
#include <stdio.h>

int main(int argc, char **argv) {
    if (argc < 2) return 2;
    FILE *f = chm_xfs_fopen(argv[1], "r");
    if (!f) {
        printf("cat: %s\n", chm_xfs_last_error());
        return 1;
    }
    char line[256];
    while (fgets(line, sizeof line, f)) printf("%s", line);
    fclose(f);
    return 0;
}
