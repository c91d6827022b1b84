#include "events.h"

#include <cerrno>
#include <cstring>

#include "log.h"

namespace tb {

bool EventLog::open(const std::string& path) {
    if (path.empty()) return true;
    path_ = path;
    // As Python's open(path, "a"): created 0666 less the umask, appended to, closed on exec,
    // and at its end (a file that cannot seek there, /proc/self/mem say, is refused; errno).
    fd_.reset(::open(path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0666));
    if (fd_.valid() && lseek(fd_.get(), 0, SEEK_END) < 0) {
        int e = errno;
        fd_.reset(-1);
        errno = e;
        return false;
    }
    return fd_.valid();
}

void EventLog::write(const char* event, int64_t step, const JsonObj& fields) {
    std::string rest = fields.text();
    std::string line = "{\"e\":" + json_quote(event) + ",\"step\":" + std::to_string(step);
    if (rest.size() > 2) line += "," + rest.substr(1, rest.size() - 2);
    line += "}\n";
    std::lock_guard<std::mutex> g(lock_);
    if (!fd_.valid()) return;
    if (cut_) line.insert(0, "\n");
    size_t done = 0;
    while (done < line.size()) {
        ssize_t n = ::write(fd_.get(), line.data() + done, line.size() - done);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) break;
        done += static_cast<size_t>(n);
    }
    if (done == line.size()) {
        cut_ = false;
        return;
    }
    int why = errno;
    cut_ = cut_ || done > 0;
    if (failed_++ == 0)
        LOG_WARN("node.events", "cannot write the event log %s: %s; events are lost (counted "
                                "in the summary's events_failed)",
                 path_.c_str(), strerror(why));
}

int64_t EventLog::failed() {
    std::lock_guard<std::mutex> g(lock_);
    return failed_;
}

void EventLog::close() {
    std::lock_guard<std::mutex> g(lock_);
    fd_.reset();
}

}  // namespace tb
