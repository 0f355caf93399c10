// LD_PRELOAD shim for tests/python/check_resume_torn.py: kills the process (SIGKILL) at its Nth write
// to a file whose name contains ".h5", the way a kill lands inside HDF5's flush of a frame. Not part of
// vksonar_tests (tests/CMakeLists.txt leaves tests/preload/ out of its sources).
//   KILL_AT_WRITE=N   the write (counted from 1, pwrite and write alike) that kills
//   KILL_PART=B       write only the first B bytes of that write before the kill (a torn write)
//   LOG_WRITES=1      one line per counted write on stderr: "W <n> <offset> <size>"
#include <dlfcn.h>
#include <signal.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>

namespace {

using PwriteFn = ssize_t (*)(int, const void*, size_t, off_t);
using WriteFn = ssize_t (*)(int, const void*, size_t);

long g_count = 0;

PwriteFn real_pwrite() {
    static auto fn = reinterpret_cast<PwriteFn>(dlsym(RTLD_NEXT, "pwrite64"));
    return fn;
}
WriteFn real_write() {
    static auto fn = reinterpret_cast<WriteFn>(dlsym(RTLD_NEXT, "write"));
    return fn;
}

bool is_h5(int fd) {
    char link[64], target[4096];
    std::snprintf(link, sizeof link, "/proc/self/fd/%d", fd);
    const ssize_t n = readlink(link, target, sizeof target - 1);
    if (n <= 0) return false;
    target[n] = '\0';
    return std::strstr(target, ".h5") != nullptr;
}

ssize_t hooked(int fd, const void* data, size_t size, off_t offset, bool positioned) {
    if (fd > 2 && is_h5(fd)) {
        const long n = ++g_count;
        if (std::getenv("LOG_WRITES")) {
            char line[96];
            const int k = std::snprintf(line, sizeof line, "W %ld %lld %zu\n", n, static_cast<long long>(offset), size);
            real_write()(2, line, static_cast<size_t>(k));
        }
        const char* at = std::getenv("KILL_AT_WRITE");
        if (at && std::atol(at) == n) {
            const char* part = std::getenv("KILL_PART");
            size_t bytes = part ? static_cast<size_t>(std::atol(part)) : size;
            if (bytes > size) bytes = size;
            if (bytes > 0) positioned ? real_pwrite()(fd, data, bytes, offset) : real_write()(fd, data, bytes);
            kill(getpid(), SIGKILL);
            for (;;)
                pause();
        }
    }
    return positioned ? real_pwrite()(fd, data, size, offset) : real_write()(fd, data, size);
}

} // namespace

extern "C" {
ssize_t pwrite(int fd, const void* data, size_t size, off_t offset) {
    return hooked(fd, data, size, offset, true);
}
ssize_t pwrite64(int fd, const void* data, size_t size, off_t offset) {
    return hooked(fd, data, size, offset, true);
}
ssize_t write(int fd, const void* data, size_t size) {
    return hooked(fd, data, size, -1, false);
}
}
