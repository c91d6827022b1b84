// See log.h.
#include "log.h"

#include <condition_variable>
#include <cstdarg>
#include <cstdio>
#include <ctime>
#include <deque>
#include <mutex>
#include <thread>
#include <unistd.h>

namespace aodv::log {

namespace {
struct Logger {
    std::string robot;
    int level = INFO;
    std::mutex mu;
    std::condition_variable cv;
    std::deque<std::string> lines;
    bool closing = false;
    std::thread thread;
};
Logger* g = nullptr;

void write_all(const std::string& text) {
    size_t off = 0;
    while (off < text.size()) {
        ssize_t n = ::write(2, text.data() + off, text.size() - off);
        if (n <= 0) return;  // stderr gone: nothing more to say
        off += size_t(n);
    }
}

void run(Logger* lg) {
    std::unique_lock<std::mutex> lock(lg->mu);
    for (;;) {
        lg->cv.wait(lock, [lg] { return !lg->lines.empty() || lg->closing; });
        std::deque<std::string> batch;
        batch.swap(lg->lines);
        bool closing = lg->closing;
        lock.unlock();
        std::string text;
        for (auto& l : batch) text += l;
        write_all(text);
        lock.lock();
        if (closing && lg->lines.empty()) return;
    }
}

const char* level_name(Level l) {
    switch (l) {
        case DEBUG: return "DEBUG";
        case INFO: return "INFO";
        case WARNING: return "WARNING";
        default: return "ERROR";
    }
}
}  // namespace

void start(const std::string& robot, const std::string& level) {
    g = new Logger;
    g->robot = robot;
    g->level = level == "debug" ? DEBUG : level == "warning" ? WARNING : level == "error" ? ERROR
                                                                                           : INFO;
    g->thread = std::thread(run, g);
}

void stop() {
    if (g == nullptr) return;
    {
        std::lock_guard<std::mutex> lock(g->mu);
        g->closing = true;
    }
    g->cv.notify_one();
    g->thread.join();
    delete g;
    g = nullptr;
}

bool enabled(Level level) { return g == nullptr || level >= g->level; }

void write(Level level, const char* name, const char* fmt, ...) {
    char msg[2048];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    // Python logging's asctime: local time, "%Y-%m-%d %H:%M:%S,mmm".
    timespec ts{};
    clock_gettime(CLOCK_REALTIME, &ts);
    tm lt{};
    localtime_r(&ts.tv_sec, &lt);
    char when[64];
    strftime(when, sizeof when, "%Y-%m-%d %H:%M:%S", &lt);
    char head[128];
    snprintf(head, sizeof head, "%s,%03ld %s %s ", when, ts.tv_nsec / 1000000, name,
             level_name(level));
    // The robot's name on every line, a message's own line breaks included.
    std::string robot = g ? g->robot : std::string("?");
    std::string text = robot + " " + head;
    for (const char* c = msg; *c; ++c) {
        text += *c;
        if (*c == '\n') text += robot + " ";
    }
    text += '\n';
    if (g == nullptr) {
        write_all(text);
        return;
    }
    {
        std::lock_guard<std::mutex> lock(g->mu);
        g->lines.push_back(std::move(text));
    }
    g->cv.notify_one();
}

}  // namespace aodv::log
