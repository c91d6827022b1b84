// Path planning and the timer (node/robot.py's _planning, _tick, _timer_rule, _timer and
// _share_map) and the coordination rules they use (node/coordination.py).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <thread>

#include "../stepcore/stepcore.h"
#include "log.h"
#include "robot.h"
#include "sched.h"

namespace tb {

namespace {
using gen::FULL_PERIOD;
using gen::GOAL_FRESH_STEPS;
using gen::REACH_STEPS;
using gen::THRESHOLD;

std::string goal_text(const Plan& p) {  // as Python prints [round(x, 3), round(y, 3)]
    if (!p.has_goal) return "null";
    return "[" + py_float(py_round(p.gx, 3)) + ", " + py_float(py_round(p.gy, 3)) + "]";
}
}  // namespace

void Robot::request(const std::string& cause) {
    {
        std::lock_guard<std::mutex> g(lock_);
        if (finished_ || plan_pending_) return;
        plan_pending_ = true;
        plan_asked_ = step_;
        plan_asked_while_sending_ = planner_sending_;
    }
    requests_.put(cause);
}

// Teammates whose map floods arrived recently (lock held).
std::vector<int> Robot::reachable() const {
    std::vector<int> out;
    for (const auto& kv : teammates_)
        if (step_ - kv.second.heard <= REACH_STEPS) out.push_back(kv.first);
    return out;
}

void Robot::planning() {
    // A test hook (NODE_PLAN_DELAY_MS), as the Python robot's: plans installed late.
    const char* d = getenv("NODE_PLAN_DELAY_MS");
    double delay = d && *d ? atof(d) / 1000 : 0;
    {
        std::string got = raise_priority(DEADLINE_RT, DEADLINE_NICE);
        std::lock_guard<std::mutex> g(count_lock_);
        priority_["planner"] = got;
    }
    const bool fallback = coordination_ == Coordination::ours;
    std::vector<uint8_t> t(static_cast<size_t>(a_.rows) * a_.cols);
    const int pad = laser_.pad;
    while (!stopping) {
        std::string cause;
        if (!requests_.get(cause, 0.5)) continue;
        if (cause.empty()) break;
        std::pair<double, double> pose;
        int64_t step;
        std::vector<int> reach;
        std::vector<std::pair<double, double>> goals;
        {
            std::lock_guard<std::mutex> g(lock_);
            sc_classify(lp_.data() + static_cast<size_t>(pad) * stride_ + pad, a_.rows, a_.cols,
                        stride_,
                        THRESHOLD, t.data());
            pose = pose_;
            step = step_;
            reach = reachable();
            for (int j : reach) {
                const Teammate& tm = teammates_.at(j);
                if (tm.goal && step - tm.goal_step <= GOAL_FRESH_STEPS) goals.push_back(*tm.goal);
            }
        }
        double t0 = monotonic_s();
        Plan p = plan(t, a_.rows, a_.cols, pose.first, pose.second, goals, a_.laser_range,
                      params_, fallback);
        double ms = (monotonic_s() - t0) * 1000;
        count(busy_, "plan", ms / 1000);
        plan_ms_.push_back(ms);
        if (delay > 0) std::this_thread::sleep_for(std::chrono::duration<double>(delay));
        // "done" goes out before the plan is installed: motion control answers no later frame
        // before it, so the world has it by the deadline the robot's answers meet.
        if (p.status == PlanStatus::done) link_.send(body_done(static_cast<uint32_t>(step)));
        {
            std::lock_guard<std::mutex> g(lock_);
            plan_ = p;
            wp_ = 0;
            plan_fresh_ = plan_asked_;
            plan_fresh_waited_ = plan_asked_while_sending_;
            last_plan_step_ = step;
            plan_pending_ = false;
            if (p.status == PlanStatus::done) finished_ = true;
        }
        caught_up_cv_.notify_all();
        std::string goal = goal_text(p);
        events_.write("plan", step,
                      JsonObj().str("cause", cause).str("status", plan_status_name(p.status))
                          .raw("goal", goal)
                          .real("cost", py_round(p.cost, 3)).real("ms", py_round(ms, 2))
                          .num("avoided", static_cast<int64_t>(goals.size())));
        LOG_INFO("node.robot", "plan at step %lld (%s): %s goal %s cost %.2f m, %.1f ms",
                 static_cast<long long>(step), cause.c_str(), plan_status_name(p.status),
                 p.has_goal ? goal.c_str() : "None", p.cost, ms);
        if (p.status == PlanStatus::done) {
            events_.write("finish", step);
            LOG_INFO("node.robot", "finished at step %lld: no reachable frontier left",
                     static_cast<long long>(step));
            continue;
        }
        if (p.status == PlanStatus::blocked) continue;  // no goal: it waits (coordination)
        std::string data = goal_msg(a_.robot, step, p.gx, p.gy, p.cost,
                                    p.status == PlanStatus::fallback,
                                    ++msg_numbers_);
        {
            std::lock_guard<std::mutex> g(lock_);
            planner_sending_ = true;
        }
        caught_up_cv_.notify_all();  // a frame held for a plan need not wait for it
        for (int j : reach) send_to(j, "goal", data, step);
        {
            std::lock_guard<std::mutex> g(lock_);
            planner_sending_ = false;
        }
        caught_up_cv_.notify_all();
    }
}

void Robot::send_to(int j, const std::string& kind, const std::string& data, int64_t step) {
    if (goals_.send(j, data)) {
        count(sent_, kind);
        events_.write("send", step, JsonObj().str("kind", kind).num("to", j));
    } else {
        count(failed_, kind);
        events_.write("send_failed", step, JsonObj().str("kind", kind).num("to", j));
    }
}

// Counts step `step` for the timer once motion control answered its frame: the timer's rule
// is evaluated here and the timer woken only for a step with work.
void Robot::tick(int64_t step) {
    std::lock_guard<std::mutex> g(lock_);
    std::optional<TimerWork> work = timer_rule(step);
    if (!work && !timer_busy_ && timer_work_.empty()) {
        timer_seen_ = step;
        return;
    }
    timer_work_.emplace_back(step, work);
    tick_cv_.notify_all();
}

// What the timer does at `step` (lock held): ask for a plan when its period passed
// (coordination: "ours" 20 steps after the last plan, "paper" on its own schedule), flood
// the local map every map period.
std::optional<TimerWork> Robot::timer_rule(int64_t step) {
    int64_t period = a_.plan_period + (!timer_fired_ ? std::max(0, a_.timer_phase) : 0);
    bool started = last_plan_step_ >= 0;
    if (started && !timer_next_tick_) timer_next_tick_ = last_plan_step_ + period;
    // coordination.timer_due_step; before the first plan there is no tick (and no plan due).
    int64_t due_step = coordination_ != Coordination::paper ? last_plan_step_ + period
                       : timer_next_tick_        ? *timer_next_tick_
                                                 : 0;
    bool plan = step >= 0 && started && !finished_ && !plan_pending_ && step >= due_step;
    while (timer_next_tick_ && *timer_next_tick_ <= step) *timer_next_tick_ += a_.plan_period;
    if (plan) timer_fired_ = true;
    int phase = std::max(0, a_.timer_phase);
    bool flood = step >= 0 && step - timer_last_map_ >= a_.map_period &&
                 step >= phase % a_.map_period;
    std::optional<int64_t> map_late;
    if (flood) {
        if (timer_last_map_ >= 0) map_late = step - timer_last_map_ - a_.map_period;
        timer_last_map_ = step;
    }
    if (!plan && !flood) return std::nullopt;
    TimerWork w;
    w.plan = plan;
    w.due_step = due_step;
    w.flood = flood;
    w.map_late = map_late;
    return w;
}

void Robot::timer() {
    {
        std::string got = raise_priority(DEADLINE_RT, DEADLINE_NICE);
        std::lock_guard<std::mutex> g(count_lock_);
        priority_["timer"] = got;
    }
    while (!stopping) {
        int64_t step, now;
        std::optional<TimerWork> work;
        {
            std::unique_lock<std::mutex> g(lock_);
            while (timer_work_.empty() && !stopping)
                tick_cv_.wait_for(g, std::chrono::milliseconds(500));
            if (timer_work_.empty()) continue;
            step = timer_work_.front().first;
            work = timer_work_.front().second;
            timer_work_.pop_front();
            timer_busy_ = true;
            now = step_;
            if (work && work->plan)
                lateness_.at("plan_timer_steps").add(static_cast<double>(now - work->due_step));
        }
        if (work && work->plan) request("timer");
        if (work && work->flood) {
            if (work->map_late) {
                std::lock_guard<std::mutex> g(lock_);
                lateness_.at("map_timer_steps")
                    .add(static_cast<double>(*work->map_late + now - step));
            }
            share_map(step);
        }
        {
            std::lock_guard<std::mutex> g(lock_);
            timer_busy_ = false;
            timer_seen_ = std::max(timer_seen_, step);
        }
        caught_up_cv_.notify_all();
    }
}

void Robot::share_map(int64_t step) {
    double t_cpu = thread_cpu_s();
    const int p = laser_.pad;
    bool full = full_wanted_.exchange(false) || step - last_full_ >= FULL_PERIOD;
    Ternary t;
    double x, y;
    Box b{0, 0, 0, 0};
    {
        std::lock_guard<std::mutex> g(lock_);
        if (full) b = {0, 0, a_.rows, a_.cols};
        else if (dirty_) b = *dirty_;
        dirty_.reset();
        t.h = std::max(0, b.r1 - b.r0);
        t.w = std::max(0, b.c1 - b.c0);
        t.cells.resize(static_cast<size_t>(t.h) * t.w);
        for (int r = 0; r < t.h; ++r)
            std::copy_n(&own_[static_cast<size_t>(p + b.r0 + r) * stride_ + p + b.c0], t.w,
                        &t.cells[static_cast<size_t>(r) * t.w]);
        x = pose_.first;
        y = pose_.second;
    }
    if (full) last_full_ = step;
    std::string payload = pack_map(x, y, t, b.r0, b.c0);
    uint32_t seq = flooder_.originate(KIND_MAP, static_cast<uint32_t>(step), payload);
    count(sent_, "map");
    events_.write("send", step, JsonObj().str("kind", "map").num("seq", seq)
                                    .num("bytes", static_cast<int64_t>(payload.size()))
                                    .boolean("full", full));
    count(busy_, "share", thread_cpu_s() - t_cpu);
}

}  // namespace tb
