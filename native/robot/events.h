// The robot's event log (node/events.py): one JSON object per line, {"e": ..., "step": ...,
// fields...}, each line one write(2) under a lock so that a robot killed mid-run leaves
// complete lines. A write that fails (a full disk) loses its event: the log counts it
// (failed(), the summary's "events_failed"), says so once on stderr, and starts its next line
// on a line of its own when a failed one was cut short, as node/events.py's EventLog does.
#pragma once

#include <cstdint>
#include <mutex>
#include <string>

#include "fd.h"
#include "json.h"

namespace tb {

class EventLog {
public:
    bool open(const std::string& path);  // "" : no log; false (errno set) when it cannot
    // `fields`: the rest of the object, as JsonObj builds it (may be empty).
    void write(const char* event, int64_t step, const JsonObj& fields = JsonObj());
    int64_t failed();  // the events lost to a failed write so far
    void close();

private:
    std::mutex lock_;  // guards everything below
    Fd fd_;
    std::string path_;
    int64_t failed_ = 0;
    bool cut_ = false;  // a failed write left part of a line: the next starts a new one
};

}  // namespace tb
