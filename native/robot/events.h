// The robot's event log (node/events.py): one JSON object per line, {"e": ..., "step": ...,
// fields...}, written whole under a lock so that a robot killed mid-run leaves complete lines.
#pragma once

#include <cstdint>
#include <cstdio>
#include <mutex>
#include <string>

#include "json.h"

namespace tb {

class EventLog {
public:
    EventLog() = default;
    ~EventLog();
    EventLog(const EventLog&) = delete;
    EventLog& operator=(const EventLog&) = delete;
    bool open(const std::string& path);  // "" : no log
    // `fields`: the rest of the object, as JsonObj builds it (may be empty).
    void write(const char* event, int64_t step, const JsonObj& fields = JsonObj());
    void close();

private:
    std::mutex lock_;  // guards f_
    FILE* f_ = nullptr;
};

}  // namespace tb
