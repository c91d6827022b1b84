#include "log.h"

#include <cstdarg>
#include <cstdio>
#include <ctime>
#include <mutex>
#include <sys/time.h>

namespace tb {

namespace {
int g_robot = 0;
std::mutex g_log_lock;  // guards stderr: one line at a time
}  // namespace

void log_init(int robot) { g_robot = robot; }

void log_line(const char* level, const char* name, const char* fmt, ...) {
    char msg[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    struct timeval tv;
    gettimeofday(&tv, nullptr);
    struct tm tm;
    localtime_r(&tv.tv_sec, &tm);
    char when[32];
    strftime(when, sizeof when, "%Y-%m-%d %H:%M:%S", &tm);
    std::lock_guard<std::mutex> g(g_log_lock);
    fprintf(stderr, "%s,%03d r%d %s %s: %s\n", when, static_cast<int>(tv.tv_usec / 1000),
            g_robot, level, name, msg);
    fflush(stderr);
}

}  // namespace tb
