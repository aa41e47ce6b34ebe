// chimera-bpcheck <file>: map a backplane file read-only and verify every
// structure in it. One line per problem, naming the field; then a summary.
// Exit status: 0 clean, 1 problems found, 2 the file cannot be read.
#include <cerrno>
#include <cstdio>
#include <cstring>

#include <unistd.h>

#include "ipc/backplane/backplane.hpp"

using namespace chm::bp;

static void print_line(void* ctx, const char* line) {
    std::printf("%s: %s\n", static_cast<const char*>(ctx), line);
}

int main(int argc, char** argv) {
    if (argc != 2 || argv[1][0] == '-') {
        std::fprintf(stderr, "usage: chimera-bpcheck <backplane file>\n"
                             "verifies the file read-only; exit 0 clean, 1 problems, 2 unreadable\n");
        return 2;
    }
    const char* path = argv[1];
    View v;
    int fd = -1;
    char why[320];
    const int r = map_file(path, false, &v, &fd, why, sizeof why, false);
    if (r == -EBADMSG) {
        std::printf("%s: %s\n", path, why);
        std::printf("%s: 1 problem (the header cannot be trusted; nothing else checked)\n", path);
        return 1;
    }
    if (r) {
        std::fprintf(stderr, "%s: unreadable: %s\n", path, why);
        return 2;
    }
    Report rep;
    rep.emit = print_line;
    rep.ctx = const_cast<char*>(path);
    Summary sum;
    check_backplane(v, rep, &sum);
    const Header* h = v.hdr();
    std::printf("%s: layout v%u, %u bytes, %u slots: %u RTPU and %u host processes live, %u dead; "
                "%u objects (%u being destroyed) of %u; common memory %llu of %llu bytes used, "
                "local windows %llu of %llu; %u recoveries\n",
                path, h->version, h->file_size, h->geo.rtpu_slots, sum.rtpus, sum.hosts, sum.dead, sum.objects,
                sum.destroying, h->geo.registry_capacity, static_cast<unsigned long long>(sum.common_used),
                static_cast<unsigned long long>(sum.common_size), static_cast<unsigned long long>(sum.local_used),
                static_cast<unsigned long long>(sum.local_size), h->recoveries.load());
    if (rep.problems) std::printf("%s: %u problem%s\n", path, rep.problems, rep.problems == 1 ? "" : "s");
    else std::printf("%s: clean\n", path);
    unmap(&v);
    ::close(fd);
    return rep.problems ? 1 : 0;
}
