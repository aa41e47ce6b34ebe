// nap_ms: sleep the calling thread about `ms` milliseconds (nanosleep; a
// signal cuts it short). Inside a Chimera task nanosleep parks only the
// task (kernel/io/blocking.cpp). The one copy for the backplane's attach
// and recovery code, the chimera tool and the multi-process tests.
#pragma once

#include <ctime>

namespace chm {

inline void nap_ms(unsigned ms) {
    timespec ts{time_t(ms / 1000), long(ms % 1000) * 1000000L};
    ::nanosleep(&ts, nullptr);
}

}  // namespace chm
