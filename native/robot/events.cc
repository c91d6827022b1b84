#include "events.h"

namespace tb {

EventLog::~EventLog() { close(); }

bool EventLog::open(const std::string& path) {
    if (path.empty()) return true;
    f_ = fopen(path.c_str(), "ae");
    return f_ != nullptr;
}

void EventLog::write(const char* event, int64_t step, const JsonObj& fields) {
    std::string rest = fields.text();
    std::string line = "{\"e\":" + json_quote(event) + ",\"step\":" + std::to_string(step);
    if (rest.size() > 2) line += "," + rest.substr(1, rest.size() - 2);
    line += "}\n";
    std::lock_guard<std::mutex> g(lock_);
    if (!f_) return;
    fwrite(line.data(), 1, line.size(), f_);
    fflush(f_);
}

void EventLog::close() {
    std::lock_guard<std::mutex> g(lock_);
    if (f_) fclose(f_);
    f_ = nullptr;
}

}  // namespace tb
