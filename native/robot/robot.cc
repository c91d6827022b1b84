// The robot's construction, start and stop (with the summary); the parts live in motion.cc,
// planning.cc and inbox.cc.
#include "robot.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <exception>
#include <unistd.h>

#include "log.h"

namespace tb {

// Python's round(): to the nearest whole number, half to even (nearbyint's default mode).
namespace {
int round_ms(double ms) { return static_cast<int>(std::nearbyint(ms)); }
}  // namespace

int RobotTimings::goal_send_timeout_ms() const {
    return std::max(gen::GOAL_SEND_TIMEOUT_MIN_MS,
                    round_ms(gen::GOAL_SEND_TIMEOUT_EMULATED_MS / time_scale));
}
int RobotTimings::goal_reconnect_min_ms() const {
    return std::max(gen::NNG_MIN_MS, round_ms(gen::GOAL_RECONNECT_MIN_EMULATED_MS / time_scale));
}
int RobotTimings::goal_reconnect_max_ms() const {
    return std::max(gen::NNG_MIN_MS, round_ms(gen::GOAL_RECONNECT_MAX_EMULATED_MS / time_scale));
}
double RobotTimings::flood_linger_s() const {
    return std::min(gen::FLOOD_LINGER_MAX_S, gen::FLOOD_LINGER_EMULATED_S / time_scale);
}

Robot::Robot(const Args& a, const RobotTimings& timing, BodyClient& link, Flooder& flooder,
             Messenger& goals, EventLog& events)
    : a_(a),
      coordination_(a.coordination == "ours" ? Coordination::ours : Coordination::paper),
      timing_(timing), link_(link), flooder_(flooder), goals_(goals), events_(events),
      laser_(a.laser_range, a.laser_rays, a.cell) {
    params_.cell = a.cell;
    params_.factor = gen::PLANNER_FACTOR;
    params_.robot_radius = a.radius;
    stride_ = a.cols + 2 * laser_.pad;
    size_t cells = static_cast<size_t>(a.rows + 2 * laser_.pad) * stride_;
    lp_.assign(cells, 0.0f);
    own_.assign(cells, 0);
    for (int j = 1; j <= a.robots; ++j)
        if (j != a.robot) teammates_[j] = Teammate();
    for (const char* k : {"plan_age_steps", "plan_age_blocked_steps", "plan_timer_steps",
                          "map_timer_steps"})
        lateness_.emplace(k, Lateness());
    lateness_.emplace("frame_answer_ms", Lateness(MS_BOUNDS));
    lateness_.emplace("order_wait_ms", Lateness(MS_BOUNDS));
    wake_pipe(wake_r_, wake_w_);  // none: the inbox notices a stop within its poll's 0.5 s
}

void Robot::count(Counter& c, const std::string& key, double v) {
    std::lock_guard<std::mutex> g(count_lock_);
    c.add(key, v);
}

// A part that dies takes the robot with it (exit status 3), as the Python robot's does.
void Robot::guarded(const char* name, void (Robot::*part)()) {
    try {
        (this->*part)();
        std::lock_guard<std::mutex> g(count_lock_);
        thread_cpu_[name] = thread_cpu_s();
    } catch (const std::exception& e) {
        LOG_ERROR("node.robot", "the %s part failed; the robot stops: %s", name, e.what());
        _exit(3);
    }
}

void Robot::run() {
    const std::pair<const char*, void (Robot::*)()> parts[] = {
        {"planner", &Robot::planning},
        {"timer", &Robot::timer},
        {"processing", &Robot::processing},
        {"inbox", &Robot::inbox},
    };
    for (const auto& p : parts) threads_.emplace_back(&Robot::guarded, this, p.first, p.second);
    for (const auto& kv : teammates_) goals_.connect(kv.first);
    laser_.prepare_tables();
    link_.ready();
    guarded("motion", &Robot::motion);
    stop();
}

namespace {
std::string median_json(const std::vector<double>& v) {
    return v.empty() ? "null" : py_float(percentile(v, 50));
}
std::string latency_json(const std::vector<double>& v) {
    JsonObj o;
    const std::pair<const char*, double> qs[] = {{"p50", 50}, {"p90", 90}, {"p99", 99},
                                                 {"max", 100}};
    for (const auto& q : qs) o.real(q.first, py_round(percentile(v, q.second) * 1000, 2));
    return o.text();
}
double peak_rss_mb() {
    FILE* f = fopen("/proc/self/status", "re");
    if (!f) return -1;
    char line[256];
    double mb = -1;
    while (fgets(line, sizeof line, f))
        if (sscanf(line, "VmHWM: %lf", &mb) == 1) {
            mb = py_round(mb / 1024, 1);
            break;
        }
    fclose(f);
    return mb;
}
}  // namespace

void Robot::stop() {
    stopping = true;
    tick_cv_.notify_all();
    requests_.put("");  // the planner's stop
    inbox_q_.put({'S', ""});
    if (wake_w_.valid()) (void)!write(wake_w_.get(), "x", 1);
    for (auto& t : threads_)
        if (t.joinable()) t.join();
    threads_.clear();
    std::lock_guard<std::mutex> g(count_lock_);
    double parts = 0;
    JsonObj tcpu;
    for (const auto& kv : thread_cpu_) {
        parts += kv.second;
        tcpu.real(kv.first, py_round(kv.second, 3));
    }
    double cpu = process_cpu_s();
    tcpu.real("other", py_round(cpu - parts, 3));  // nng's threads, start-up
    JsonObj prio;
    for (const auto& kv : priority_) prio.str(kv.first, kv.second);
    JsonObj late;
    for (const char* k : {"plan_age_steps", "plan_age_blocked_steps", "plan_timer_steps",
                          "map_timer_steps", "frame_answer_ms", "order_wait_ms"})
        late.raw(k, lateness_.at(k).json());
    JsonObj lat;
    if (!delivery_.empty()) lat.raw("delivery", latency_json(delivery_));
    if (!answer_.empty()) lat.raw("answer", latency_json(answer_));
    double rss = peak_rss_mb();
    bool finished;
    int64_t step;
    {
        std::lock_guard<std::mutex> gl(lock_);
        finished = finished_;
        step = step_;
    }
    JsonObj o;
    o.raw("sent", sent_.json_int()).raw("received", received_.json_int());
    o.raw("send_failed", failed_.json_int());
    o.num("malformed", malformed_ + static_cast<int64_t>(flooder_.count("malformed")));
    o.raw("flood", flooder_.counts_json()).raw("maps", flooder_.stats.json());
    o.num("frames", frames_).num("frames_skipped", skipped_);
    o.num("order_timeouts", order_timeouts_).num("inbox_dropped", inbox_dropped_);
    o.raw("plan_ms_median", median_json(plan_ms_));
    o.real("cpu_s", py_round(cpu, 3));
    o.raw("max_rss_mb", rss < 0 ? "null" : py_float(rss));
    o.raw("busy_s", busy_.json_real(3)).raw("thread_cpu_s", tcpu.text());
    o.raw("priority", prio.text()).raw("lateness", late.text()).raw("latency_ms", lat.text());
    o.boolean("finished", finished).str("middleware", goals_.name());
    o.raw("messenger", goals_.stats.json()).raw("arrivals", arrivals_.json());
    o.num("events_failed", events_.failed()).str("robot_impl", "cpp");
    events_.write("summary", step, o);
}

}  // namespace tb
