// Logging with the robot's name on every line, in the Python robot's format:
// "2026-01-01 12:00:00,123 r3 INFO node.robot: message" on stderr (the robot's log file).
#pragma once

#include <string>

namespace tb {

void log_init(int robot);
void log_line(const char* level, const char* name, const char* fmt, ...)
    __attribute__((format(printf, 3, 4)));

#define LOG_INFO(name, ...) ::tb::log_line("INFO", name, __VA_ARGS__)
#define LOG_WARN(name, ...) ::tb::log_line("WARNING", name, __VA_ARGS__)
#define LOG_ERROR(name, ...) ::tb::log_line("ERROR", name, __VA_ARGS__)

}  // namespace tb
