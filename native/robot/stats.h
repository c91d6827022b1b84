// What the robot counts for its summary (robots/rK.json), as the Python robot counts it:
// lateness books (node/lateness.py), counters in first-use order (collections.Counter), the
// map transport's and the messenger's counters (node/mapstats.py, node/messaging/stats.py),
// arrivals (node/messaging/arrivals.py) and percentiles as numpy computes them.
#pragma once

#include <cstdint>
#include <map>
#include <mutex>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "robot_consts.h"

namespace tb {

double monotonic_s();   // time.monotonic()
double thread_cpu_s();  // time.thread_time()
double process_cpu_s(); // time.process_time()

extern const std::vector<double> STEP_BOUNDS;  // node.lateness's, in steps

class Lateness {
public:
    explicit Lateness(std::vector<double> bounds = STEP_BOUNDS);
    void add(double late);
    std::string json() const;

private:
    std::vector<double> bounds_;
    std::vector<int64_t> counts_;
    int64_t n_ = 0, late_ = 0;
    double max_ = 0;
};
extern const std::vector<double> MS_BOUNDS;  // node.lateness's, in emulated ms

// A Counter: keys in the order first counted; only counted keys appear.
class Counter {
public:
    void add(const std::string& key, double v = 1);
    double get(const std::string& key) const;
    std::string json_int() const;          // values as integers
    std::string json_real(int digits) const;  // values rounded
    bool empty() const { return items_.empty(); }

private:
    std::vector<std::pair<std::string, double>> items_;
};

struct MapStats {
    std::mutex lock;  // guards everything below (timer publishes, inbox receives)
    int64_t published = 0, failed = 0, bytes_published = 0, received = 0, bytes_received = 0;
    std::map<int, int64_t> received_from;
    double blocked_s = 0, blocked_max_s = 0;
    void note_publish(size_t size, bool ok, double seconds);
    void note_receive(int origin, size_t size);
    std::string json();
};

struct MessengerStats {
    std::mutex lock;  // guards everything below (planner and processing both send)
    int64_t sent = 0, failed = 0, received = 0;
    double blocked_s = 0, blocked_max_s = 0;
    std::map<int64_t, double> open;  // sends in progress: token -> start
    int64_t next_token = 0;
    int64_t send_started();
    void send_ended(int64_t token, bool ok);
    std::string json();
};

struct Arrivals {
    std::map<int, std::set<int64_t>> seen;
    int64_t messages = 0, duplicates = 0, late = 0, delay_steps_max = 0;
    void note(int sender, int64_t n, int64_t sent_step, int64_t step);
    std::string json() const;
};

double percentile(std::vector<double> v, double q);  // numpy's linear interpolation

}  // namespace tb
