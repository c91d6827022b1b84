#include "stats.h"

#include <algorithm>
#include <cmath>
#include <ctime>
#include <iterator>

#include "json.h"

namespace tb {

const std::vector<double> STEP_BOUNDS(std::begin(gen::STEP_BOUNDS), std::end(gen::STEP_BOUNDS));
const std::vector<double> MS_BOUNDS(std::begin(gen::MS_BOUNDS), std::end(gen::MS_BOUNDS));

namespace {
double clock_s(clockid_t id) {
    timespec t;
    clock_gettime(id, &t);
    return static_cast<double>(t.tv_sec) + t.tv_nsec * 1e-9;
}
std::string label(double b) {
    return b == std::floor(b) ? std::to_string(static_cast<int64_t>(b)) : py_float(b);
}
}  // namespace

double monotonic_s() { return clock_s(CLOCK_MONOTONIC); }
double thread_cpu_s() { return clock_s(CLOCK_THREAD_CPUTIME_ID); }
double process_cpu_s() { return clock_s(CLOCK_PROCESS_CPUTIME_ID); }

Lateness::Lateness(std::vector<double> bounds)
    : bounds_(std::move(bounds)), counts_(bounds_.size() + 1, 0) {}

void Lateness::add(double late) {
    ++n_;
    if (late > 0) ++late_;
    if (late > max_) max_ = late;
    for (size_t i = 0; i < bounds_.size(); ++i)
        if (late <= bounds_[i]) {
            ++counts_[i];
            return;
        }
    ++counts_.back();
}

std::string Lateness::json() const {
    JsonObj hist;
    for (size_t i = 0; i < bounds_.size(); ++i) hist.num("<=" + label(bounds_[i]), counts_[i]);
    hist.num(">" + label(bounds_.back()), counts_.back());
    JsonObj o;
    o.num("n", n_).num("late", late_);
    // round(max, 3): an int stays an int in Python (steps), a float is a float.
    double m = py_round(max_, 3);
    bool whole = m > 0 && m == std::floor(m) && bounds_[0] == 0;
    o.raw("max", whole ? std::to_string(static_cast<int64_t>(m)) : py_float(m));
    o.raw("hist", hist.text());
    return o.text();
}

void Counter::add(const std::string& key, double v) {
    for (auto& kv : items_)
        if (kv.first == key) {
            kv.second += v;
            return;
        }
    items_.emplace_back(key, v);
}

double Counter::get(const std::string& key) const {
    for (const auto& kv : items_)
        if (kv.first == key) return kv.second;
    return 0;
}

std::string Counter::json_int() const {
    JsonObj o;
    for (const auto& kv : items_) o.num(kv.first, static_cast<int64_t>(kv.second));
    return o.text();
}

std::string Counter::json_real(int digits) const {
    JsonObj o;
    for (const auto& kv : items_) o.real(kv.first, py_round(kv.second, digits));
    return o.text();
}

void MapStats::note_publish(size_t size, bool ok, double seconds) {
    std::lock_guard<std::mutex> g(lock);
    if (ok) {
        ++published;
        bytes_published += static_cast<int64_t>(size);
    } else {
        ++failed;
    }
    blocked_s += seconds;
    blocked_max_s = std::max(blocked_max_s, seconds);
}

void MapStats::note_receive(int origin, size_t size) {
    std::lock_guard<std::mutex> g(lock);
    ++received;
    bytes_received += static_cast<int64_t>(size);
    ++received_from[origin];
}

std::string MapStats::json() {
    std::lock_guard<std::mutex> g(lock);
    JsonObj from;
    for (const auto& kv : received_from) from.num("r" + std::to_string(kv.first), kv.second);
    JsonObj o;
    o.str("transport", "flood").num("published", published).num("failed", failed);
    o.num("bytes_published", bytes_published).num("received", received);
    o.num("bytes_received", bytes_received).raw("received_from", from.text());
    o.real("blocked_s", py_round(blocked_s, 6)).real("blocked_max_s", py_round(blocked_max_s, 6));
    return o.text();
}

int64_t MessengerStats::send_started() {
    std::lock_guard<std::mutex> g(lock);
    int64_t t = next_token++;
    open[t] = monotonic_s();
    return t;
}

void MessengerStats::send_ended(int64_t token, bool ok) {
    double now = monotonic_s();
    std::lock_guard<std::mutex> g(lock);
    double s = now - open[token];
    open.erase(token);
    blocked_s += s;
    blocked_max_s = std::max(blocked_max_s, s);
    if (ok) ++sent;
    else ++failed;
}

std::string MessengerStats::json() {
    double now = monotonic_s();
    std::lock_guard<std::mutex> g(lock);
    double blocked = blocked_s, longest = blocked_max_s;
    for (const auto& kv : open) {
        blocked += now - kv.second;
        longest = std::max(longest, now - kv.second);
    }
    JsonObj o;
    o.num("sent", sent).num("failed", failed).num("received", received);
    o.real("blocked_s", py_round(blocked, 6)).real("blocked_max_s", py_round(longest, 6));
    o.num("sending", static_cast<int64_t>(open.size()));
    return o.text();
}

void Arrivals::note(int sender, int64_t n, int64_t sent_step, int64_t step) {
    ++messages;
    int64_t delay = step - sent_step;
    delay_steps_max = std::max(delay_steps_max, delay);
    if (delay > gen::LATE_STEPS) ++late;
    if (n <= 0) return;
    if (!seen[sender].insert(n).second) ++duplicates;
}

std::string Arrivals::json() const {
    JsonObj o;
    o.num("messages", messages).num("duplicates", duplicates).num("late", late);
    o.num("delay_steps_max", delay_steps_max);
    return o.text();
}

double percentile(std::vector<double> v, double q) {
    std::sort(v.begin(), v.end());
    double pos = (q / 100.0) * static_cast<double>(v.size() - 1);
    size_t lo = static_cast<size_t>(std::floor(pos));
    size_t hi = std::min(lo + 1, v.size() - 1);
    double frac = pos - static_cast<double>(lo);
    return v[lo] + (v[hi] - v[lo]) * frac;
}

}  // namespace tb
