// The crash-point test's shim (tests/crash_points_test.py, docs/results.md "One commit per part"),
// loaded into hotgauged with LD_PRELOAD: at one chosen file operation it kills the process
// (SIGKILL, as a crash or a power cut would stop it there) or makes the disk full from then on.
//
//   HG_CRASH_GLOB  which files: fnmatch(3) pattern on the absolute path ("*/results/*.csv")
//   HG_CRASH_OP    which operation on them: write (write, pwrite), sync (fsync, fdatasync),
//                  mkdir, rename (the path is the source's)
//   HG_CRASH_MODE  kill: SIGKILL before the operation; full: the operation and every later write,
//                  sync, mkdir and rename under HG_CRASH_ROOT fail with ENOSPC
//   HG_CRASH_ROOT  the folder that is full in mode full (the line's working folder)
//   HG_CRASH_ARM   a file: nothing happens while it does not exist (the test creates it just
//                  before the part, so that the start's own writes pass)
// Without HG_CRASH_GLOB the shim passes everything through.
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <fnmatch.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <unistd.h>

enum Op { kWrite, kSync, kMkdir, kRename };

static int disk_full = 0;  // mode full, once hit

static const char* env(const char* name) {
    const char* v = getenv(name);
    return v && *v ? v : NULL;
}

static int fd_path(int fd, char* out, size_t size) {
    char link[64];
    snprintf(link, sizeof link, "/proc/self/fd/%d", fd);
    const ssize_t n = readlink(link, out, size - 1);
    if (n <= 0) return 0;
    out[n] = '\0';
    return 1;
}

static int under_root(const char* path) {
    const char* root = env("HG_CRASH_ROOT");
    return root && strncmp(path, root, strlen(root)) == 0;
}

// 0: go on; -1: fail with ENOSPC. Does not return in mode kill.
static int decide(enum Op op, const char* path) {
    static const char* const names[] = {"write", "sync", "mkdir", "rename"};
    const char* glob = env("HG_CRASH_GLOB");
    if (!glob || !path) return 0;
    if (disk_full) return under_root(path) ? -1 : 0;
    const char* want = env("HG_CRASH_OP");
    if (!want || strcmp(want, names[op]) != 0 || fnmatch(glob, path, 0) != 0) return 0;
    const char* arm = env("HG_CRASH_ARM");
    if (arm && access(arm, F_OK) != 0) return 0;
    const char* mode = env("HG_CRASH_MODE");
    if (mode && strcmp(mode, "full") == 0) {
        disk_full = 1;
        return -1;
    }
    kill(getpid(), SIGKILL);
    for (;;) pause();
}

static int decide_fd(enum Op op, int fd) {
    if (!env("HG_CRASH_GLOB") || fd <= 2) return 0;
    char path[4096];
    return fd_path(fd, path, sizeof path) ? decide(op, path) : 0;
}

#define REAL(name, type) ((type)dlsym(RTLD_NEXT, name))

ssize_t write(int fd, const void* buf, size_t n) {
    if (decide_fd(kWrite, fd) < 0) return errno = ENOSPC, -1;
    return REAL("write", ssize_t(*)(int, const void*, size_t))(fd, buf, n);
}

ssize_t pwrite(int fd, const void* buf, size_t n, off_t at) {
    if (decide_fd(kWrite, fd) < 0) return errno = ENOSPC, -1;
    return REAL("pwrite", ssize_t(*)(int, const void*, size_t, off_t))(fd, buf, n, at);
}

ssize_t pwrite64(int fd, const void* buf, size_t n, off_t at) {
    if (decide_fd(kWrite, fd) < 0) return errno = ENOSPC, -1;
    return REAL("pwrite64", ssize_t(*)(int, const void*, size_t, off_t))(fd, buf, n, at);
}

int fsync(int fd) {
    if (decide_fd(kSync, fd) < 0) return errno = ENOSPC, -1;
    return REAL("fsync", int (*)(int))(fd);
}

int fdatasync(int fd) {
    if (decide_fd(kSync, fd) < 0) return errno = ENOSPC, -1;
    return REAL("fdatasync", int (*)(int))(fd);
}

int mkdir(const char* path, mode_t mode) {
    if (decide(kMkdir, path) < 0) return errno = ENOSPC, -1;
    return REAL("mkdir", int (*)(const char*, mode_t))(path, mode);
}

int rename(const char* from, const char* to) {
    if (decide(kRename, from) < 0) return errno = ENOSPC, -1;
    return REAL("rename", int (*)(const char*, const char*))(from, to);
}
