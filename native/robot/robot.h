// The robot role (node/robot.py): the paper's five concurrent parts around three shared
// structures. Shared, under `lock_`: the map (log-odds, padded for the laser) with the
// robot's own observations kept apart as its local map, the current plan, and the scans
// archive. Five threads, each with the Python robot's job and priority:
//
// - motion control (the calling thread, SCHED_RR 1): a frame from the body link into the
//   maps, a step along the plan, one command back; counts the steps for the timer;
// - path planning (SCHED_RR 1): plans on request on a snapshot of the map (the step core's
//   planner), installs the plan, announces the goal to reachable teammates;
// - timer (SCHED_RR 1): asks for a plan when one is due and floods the local map every
//   map period, for the steps motion control found work at;
// - message processing: merges maps, records teammates' goals, settles goal conflicts;
// - inbox: receives floods (relayed on the way) and messages into a bounded queue.
//
// Every plan, send and receipt goes to the event log with the step (node/events.py's lines).
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "args.h"
#include "body.h"
#include "events.h"
#include "fd.h"
#include "flood.h"
#include "laser.h"
#include "messenger.h"
#include "planner.h"
#include "robot_consts.h"
#include "stats.h"

namespace tb {

// node/timing.py's RobotTimings: every wall duration, from the time scale, by the same
// formulas on the same numbers (build/gen/robot_consts.h, generated from node.timing;
// `tb-robot --timings SCALE MAP_PERIOD` prints them for tests/unit/test_robot_consts.py).
struct RobotTimings {
    double time_scale = 1.0;
    int map_period = 10;
    double step_order_wait_s() const {
        return gen::STEP_ORDER_WAIT_STEPS * gen::STEP_S / time_scale;
    }
    double neighbour_hold_s() const {
        return gen::NEIGHBOUR_HOLD_MAP_PERIODS * map_period * gen::STEP_S / time_scale;
    }
    int goal_send_timeout_ms() const;
    int goal_reconnect_min_ms() const;
    int goal_reconnect_max_ms() const;
    double flood_linger_s() const;
};

// How goals are agreed (node/coordination.py's MODES; --coordination, checked by args.cc).
enum class Coordination { paper, ours };

struct Teammate {
    int64_t heard = -1000000000;
    std::optional<std::pair<double, double>> goal;
    double cost = 0;
    int64_t goal_step = -1000000000;
    std::optional<std::pair<double, double>> pos;
};

struct Box {
    int r0, c0, r1, c1;
};

struct TimerWork {
    bool plan = false;
    int64_t due_step = 0;
    bool flood = false;
    std::optional<int64_t> map_late;
};

// A FIFO with a bound (0: none) between two threads.
template <typename T>
class Queue {
public:
    explicit Queue(size_t limit = 0) : limit_(limit) {}
    bool put(T v) {
        {
            std::lock_guard<std::mutex> g(m_);
            if (limit_ && q_.size() >= limit_) return false;
            q_.push_back(std::move(v));
        }
        cv_.notify_one();
        return true;
    }
    bool get(T& out, double timeout_s) {
        std::unique_lock<std::mutex> g(m_);
        if (!cv_.wait_for(g, std::chrono::duration<double>(timeout_s), [&] { return !q_.empty(); }))
            return false;
        out = std::move(q_.front());
        q_.pop_front();
        return true;
    }

private:
    std::mutex m_;  // guards q_
    std::condition_variable cv_;
    std::deque<T> q_;
    size_t limit_;
};

class Robot {
public:
    Robot(const Args& a, const RobotTimings& timing, BodyClient& link, Flooder& flooder,
          Messenger& goals, EventLog& events);
    void run();   // starts the other four parts, runs motion control until the run ends
    void stop();  // stops the parts and writes the summary
    std::atomic<bool> stopping{false};

private:
    // motion.cc
    void motion();
    void keep_step_order(const Frame& f);
    void put_scan(const Frame& f);
    Box footprint(double x, double y) const;
    std::optional<std::pair<double, double>> follow(bool moved);
    void plan_applied(int64_t step);
    // planning.cc
    void request(const std::string& cause);
    void planning();
    void send_to(int j, const std::string& kind, const std::string& data, int64_t step);
    std::vector<int> reachable() const;
    void tick(int64_t step);
    std::optional<TimerWork> timer_rule(int64_t step);
    void timer();
    void share_map(int64_t step);
    // inbox.cc
    void inbox();
    void processing();
    bool on_flood(const std::string& data, std::string& err);
    bool on_message(const std::string& data, std::string& err);
    // robot.cc
    void count(Counter& c, const std::string& key, double v = 1);
    void guarded(const char* name, void (Robot::*part)());

    const Args a_;
    const Coordination coordination_;
    const RobotTimings timing_;
    BodyClient& link_;
    Flooder& flooder_;
    Messenger& goals_;
    EventLog& events_;
    Laser laser_;
    PlannerParams params_;
    int stride_;  // row length of the padded maps

    // --- shared state, guarded by lock_ ---
    std::mutex lock_;
    std::condition_variable tick_cv_, caught_up_cv_;
    std::vector<float> lp_;      // log-odds, padded
    std::vector<uint8_t> own_;   // the local map (ternary), padded
    std::vector<Frame> scans_;   // the archive
    std::optional<Plan> plan_;
    size_t wp_ = 0;
    std::pair<double, double> pose_{0, 0};
    int64_t step_ = -1, last_plan_step_ = -1000000000;
    std::optional<Box> dirty_;
    bool plan_pending_ = false;
    int64_t plan_asked_ = -1;
    std::optional<int64_t> plan_fresh_;
    bool planner_sending_ = false, plan_asked_while_sending_ = false, plan_fresh_waited_ = false;
    bool finished_ = false;
    std::map<int, Teammate> teammates_;
    std::deque<std::pair<int64_t, std::optional<TimerWork>>> timer_work_;
    bool timer_busy_ = false;
    bool timer_fired_ = false;
    std::optional<int64_t> timer_next_tick_;
    int64_t timer_last_map_ = -1000000000;
    int64_t timer_seen_ = -1;
    std::map<std::string, Lateness> lateness_;
    // --- end of lock_'s ---

    std::mutex count_lock_;  // guards the counters below (several threads count)
    Counter sent_, received_, failed_, busy_;
    std::map<std::string, double> thread_cpu_;
    std::map<std::string, std::string> priority_;
    std::vector<double> plan_ms_;  // the planner's alone until stop()
    std::vector<double> delivery_, answer_;  // motion control's alone until stop()
    Arrivals arrivals_;  // processing's alone until stop()
    std::atomic<int64_t> malformed_{0};
    int64_t order_timeouts_ = 0, frames_ = 0, skipped_ = 0;  // motion control's
    std::atomic<int64_t> inbox_dropped_{0}, msg_numbers_{0};
    int stuck_ = 0;                       // motion control's
    int64_t last_full_ = -1000000000;     // the timer's
    std::atomic<bool> full_wanted_{false};
    std::map<int, int64_t> last_heard_;   // processing's

    Queue<std::string> requests_;
    Queue<std::pair<char, std::string>> inbox_q_{gen::INBOX_LIMIT};
    Fd wake_r_, wake_w_;  // stop() wakes the inbox's poll
    std::vector<std::thread> threads_;
};

}  // namespace tb
