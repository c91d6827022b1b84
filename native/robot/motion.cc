// Motion control (node/robot.py's _motion and its helpers): the main thread.
#include <algorithm>
#include <chrono>
#include <cmath>

#include "../stepcore/stepcore.h"
#include "log.h"
#include "robot.h"
#include "sched.h"

namespace tb {

namespace {
using gen::FREE;
using gen::L_FREE;
using gen::L_MAX;
using gen::L_OCC;
using gen::OCC;
using gen::STUCK_FRAMES;

Box grow(const std::optional<Box>& a, const Box& b) {
    if (!a) return b;
    return {std::min(a->r0, b.r0), std::min(a->c0, b.c0), std::max(a->r1, b.r1),
            std::max(a->c1, b.c1)};
}
}  // namespace

void Robot::motion() {
    // Real-time priority 1, one below the world's clock (common/sched.py).
    {
        std::string got = raise_priority(DEADLINE_RT, DEADLINE_NICE);
        std::lock_guard<std::mutex> g(count_lock_);
        priority_["motion"] = got;
    }
    bool started = false;
    std::optional<std::pair<double, double>> last_xy;
    BodyMsg msg;
    std::string err;
    // A frame off the map or of another ray count is refused as malformed (body.cc).
    link_.expect(a_.cols * a_.cell, a_.rows * a_.cell, laser_.n_rays);
    while (!stopping) {
        int got = link_.recv(0.5, msg, err);
        if (got < 0) {
            ++malformed_;
            LOG_WARN("node.robot", "dropped a malformed body message: %s", err.c_str());
            continue;
        }
        if (got == 0) continue;
        if (msg.kind == BodyKind::end) {
            std::lock_guard<std::mutex> g(lock_);
            LOG_INFO("node.robot", "the world ended the run at step %lld",
                     static_cast<long long>(step_));
            return;
        }
        if (msg.kind != BodyKind::frame) continue;
        const Frame& f = msg.frame;
        ++frames_;
        keep_step_order(f);
        double t_frame = thread_cpu_s();
        double t_in = monotonic_s();
        // A robot standing still sees nothing new (the world is static): skip the update.
        bool moved = !last_xy || last_xy->first != f.x || last_xy->second != f.y;
        last_xy = std::make_pair(f.x, f.y);
        bool behind = link_.pending();
        std::optional<std::pair<double, double>> target;
        {
            std::lock_guard<std::mutex> g(lock_);
            if (moved) {
                put_scan(f);
                dirty_ = grow(dirty_, footprint(f.x, f.y));
            }
            pose_ = {f.x, f.y};
            step_ = f.step;
            scans_.push_back(f);
            if (!behind) target = follow(moved);
            if (!behind && plan_fresh_) plan_applied(f.step);
        }
        if (behind) {
            ++skipped_;  // a newer frame is waiting: act on that one
        } else {
            link_.send(body_cmd(f.step, target.has_value(), target ? target->first : 0,
                                target ? target->second : 0));
        }
        count(busy_, "motion", thread_cpu_s() - t_frame);
        double t_out = monotonic_s();
        if (f.sent > 0) {
            delivery_.push_back(t_in - f.sent);
            if (!behind) {
                double lag_ms = (t_out - f.sent) * 1000 * timing_.time_scale;
                std::lock_guard<std::mutex> g(lock_);
                lateness_.at("frame_answer_ms").add(lag_ms);
            }
        }
        answer_.push_back(t_out - t_in);
        tick(f.step);
        if (!started) {
            started = true;
            request("start");
        }
    }
}

void Robot::plan_applied(int64_t step) {
    const char* age = plan_fresh_waited_ ? "plan_age_blocked_steps" : "plan_age_steps";
    lateness_.at(age).add(static_cast<double>(step - *plan_fresh_ - 1));
    plan_fresh_.reset();
}

// Holds frame `f` until the timer and the planner finished the previous step's work, but only
// until three quarters of a step after the world sent it (node/robot.py's _keep_step_order).
void Robot::keep_step_order(const Frame& f) {
    auto caught_up = [&] {
        if (stopping || step_ < 0) return true;
        bool waiting = plan_pending_ && plan_asked_ < f.step && !planner_sending_;
        return timer_seen_ >= step_ && !waiting;
    };
    std::unique_lock<std::mutex> g(lock_);
    if (caught_up()) return;
    double t0 = monotonic_s();
    double until = (f.sent > 0 ? f.sent : t0) + timing_.step_order_wait_s();
    bool ok = caught_up_cv_.wait_for(
        g, std::chrono::duration<double>(std::max(0.0, until - t0)), caught_up);
    lateness_.at("order_wait_ms").add((monotonic_s() - t0) * 1000 * timing_.time_scale);
    if (!ok) ++order_timeouts_;
}

// One scan into the map and the local map (lock held): the step core's sc_scan_into, or the
// per-cell form where the laser's window sticks out of the padded map.
void Robot::put_scan(const Frame& f) {
    const Laser& L = laser_;
    float fx = static_cast<float>(f.x / L.cell + BIAS);
    float fy = static_cast<float>(f.y / L.cell + BIAS);
    const int ify = static_cast<int>(fy), ifx = static_cast<int>(fx);
    int r0 = ify - BIAS, c0 = ifx - BIAS, w = L.window;
    int height = a_.rows + 2 * L.pad;
    // A scan of another ray count is refused before (BodyClient::expect); were one to come
    // here, it is cut or padded with "nothing hit" rather than read past its end.
    static thread_local std::vector<float> padded;
    const std::vector<float>* rp = &f.ranges;
    if (static_cast<int>(f.ranges.size()) != L.n_rays) {
        padded = f.ranges;
        padded.resize(L.n_rays, INFINITY);
        rp = &padded;
    }
    const std::vector<float>& ranges = *rp;
    if (r0 >= 0 && c0 >= 0 && r0 + w <= height && c0 + w <= stride_) {
        static thread_local std::vector<uint8_t> free_tmp;
        static thread_local std::vector<int64_t> occ_tmp;
        free_tmp.resize(static_cast<size_t>(w) * w);
        occ_tmp.resize(L.n_rays);
        const MarkTable* t = L.table_for(fx, fy);
        sc_scan_into(L.dx.data(), L.dy.data(), L.mark.data(), L.n_rays, L.n_samples, L.step32,
                     w, fx, fy, L.pad - ify, L.pad - ifx, ranges.data(), lp_.data(),
                     own_.data(), stride_, r0, c0, L_FREE, L_OCC, L_MAX, free_tmp.data(),
                     occ_tmp.data(), t ? t->sure.data() : nullptr, t ? t->odx.data() : nullptr,
                     t ? t->ody.data() : nullptr, t ? static_cast<int>(t->odx.size()) : 0);
        return;
    }
    // Laser.scan_cells + OccupancyGrid.update_cells: every cell once, free first.
    int64_t base = static_cast<int64_t>(L.pad - BIAS) * stride_ + (L.pad - BIAS);
    int64_t total = static_cast<int64_t>(lp_.size());
    std::vector<int64_t> free_cells, occ_cells;
    for (int k = 0; k < L.n_rays; ++k) {
        float r = ranges[k];
        int idx = L.n_samples;
        if (std::isfinite(r))
            idx = std::min(std::max(static_cast<int>(std::nearbyintf(r / L.step32)) - 1, 0),
                           L.n_samples);
        for (int s = 0; s <= std::min(idx, L.n_samples - 1); ++s) {
            size_t i = static_cast<size_t>(k) * L.n_samples + s;
            int64_t at = static_cast<int64_t>(static_cast<int32_t>(L.dy[i] + fy)) * stride_ +
                         static_cast<int32_t>(L.dx[i] + fx) + base;
            if (at < 0 || at >= total) continue;
            if (s < idx && L.mark[i]) free_cells.push_back(at);
            if (s == idx) occ_cells.push_back(at);
        }
    }
    for (auto* cells : {&free_cells, &occ_cells}) {
        std::sort(cells->begin(), cells->end());
        cells->erase(std::unique(cells->begin(), cells->end()), cells->end());
    }
    for (int64_t at : free_cells) lp_[at] = std::max(lp_[at] + L_FREE, -L_MAX);
    for (int64_t at : occ_cells) lp_[at] = std::min(lp_[at] + L_OCC, L_MAX);
    for (int64_t at : free_cells) own_[at] = FREE;
    for (int64_t at : occ_cells) own_[at] = OCC;
}

Box Robot::footprint(double x, double y) const {
    double c = a_.cell, rng = a_.laser_range;
    auto cell = [c](double v) { return static_cast<int>(v / c); };
    return {std::max(0, cell(y - rng) - 1), std::max(0, cell(x - rng) - 1),
            std::min(a_.rows, cell(y + rng) + 2), std::min(a_.cols, cell(x + rng) + 2)};
}

// The next waypoint of the current plan (lock held); a robot that has not moved for
// STUCK_FRAMES frames while driving gives up that waypoint for the next one.
std::optional<std::pair<double, double>> Robot::follow(bool moved) {
    if (finished_ || !plan_) return std::nullopt;
    const auto& path = plan_->path;
    double tol = gen::WAYPOINT_TOL_M + gen::WAYPOINT_TOL_SPEEDS * a_.speed;
    while (wp_ < path.size() &&
           std::hypot(pose_.first - path[wp_].first, pose_.second - path[wp_].second) <= tol)
        ++wp_;
    stuck_ = (moved || wp_ >= path.size()) ? 0 : stuck_ + 1;
    if (stuck_ >= STUCK_FRAMES) {
        stuck_ = 0;
        ++wp_;
        LOG_INFO("node.robot", "stuck at (%s, %s): skipping a waypoint",
                 py_float(py_round(pose_.first, 2)).c_str(),
                 py_float(py_round(pose_.second, 2)).c_str());
    }
    if (wp_ < path.size()) return path[wp_];
    return std::nullopt;
}

}  // namespace tb
