// Log lines of the compiled AODV daemon, as aodv/__main__.py formats them:
//
//     r3 2026-11-29 05:50:25,123 aodv.daemon INFO AODV up on wlan0 (10.0.0.3), time scale 1
//
// the robot's name first on every line, then the time, the logger's name, the level and
// the message. Lines go through a queue to a thread that writes them to stderr (as the
// Python daemon's QueueListener): the loop never waits on its log file.
#pragma once

#include <string>

namespace aodv::log {

enum Level { DEBUG = 10, INFO = 20, WARNING = 30, ERROR = 40 };

// Start the writer thread; `level` is one of debug, info, warning, error.
void start(const std::string& robot, const std::string& level);
// Write what is queued and stop the thread (idempotent).
void stop();
bool enabled(Level level);
// One line from logger `name` (e.g. "aodv.daemon"), printf-style.
void write(Level level, const char* name, const char* fmt, ...)
    __attribute__((format(printf, 3, 4)));

}  // namespace aodv::log

#define AODV_LOG(level, name, ...)                                                 \
    do {                                                                           \
        if (::aodv::log::enabled(::aodv::log::level))                              \
            ::aodv::log::write(::aodv::log::level, name, __VA_ARGS__);             \
    } while (0)
