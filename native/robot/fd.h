// An owning file descriptor: closed when its owner goes, moved but never copied, so that
// every descriptor the robot opens (its wake pipes, the flood socket, the body link, the event
// log) has one owner and is closed exactly once.
#pragma once

#include <fcntl.h>
#include <unistd.h>

namespace tb {

class Fd {
public:
    Fd() = default;
    explicit Fd(int fd) : fd_(fd) {}
    ~Fd() { reset(); }
    Fd(const Fd&) = delete;
    Fd& operator=(const Fd&) = delete;
    Fd(Fd&& o) noexcept : fd_(o.release()) {}
    Fd& operator=(Fd&& o) noexcept {
        if (this != &o) reset(o.release());
        return *this;
    }

    int get() const { return fd_; }
    bool valid() const { return fd_ >= 0; }
    // The descriptor, no longer owned (the caller closes it).
    int release() {
        int fd = fd_;
        fd_ = -1;
        return fd;
    }
    // Closes the one owned (if any) and owns `fd` instead.
    void reset(int fd = -1) {
        if (fd_ >= 0) ::close(fd_);
        fd_ = fd;
    }

private:
    int fd_ = -1;
};

// A pipe whose write end wakes a thread polling its read end (non-blocking, closed on exec);
// false (both left invalid) when the system has no descriptor left.
inline bool wake_pipe(Fd& r, Fd& w) {
    int p[2];
    if (pipe2(p, O_CLOEXEC | O_NONBLOCK) != 0) return false;
    r.reset(p[0]);
    w.reset(p[1]);
    return true;
}

}  // namespace tb
