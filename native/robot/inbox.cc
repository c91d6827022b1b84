// The inbox and message processing (node/robot.py's _inbox, _processing, _on_flood and
// _on_message), with the coordination rules on a teammate's goal or request.
#include <chrono>
#include <poll.h>
#include <thread>
#include <unistd.h>

#include "../stepcore/stepcore.h"
#include "log.h"
#include "robot.h"

namespace tb {

namespace {
using gen::MERGED;
using gen::REACH_STEPS;
using gen::THRESHOLD;
constexpr char FLOOD = 'F', MESSAGE = 'M', STOP = 'S';

// planner.goal_priority: the shorter path wins, then the lower robot number.
bool higher_priority(double my_cost, int me, double other_cost, int other) {
    double a = py_round(my_cost, 3), b = py_round(other_cost, 3);
    return a < b || (a == b && me < other);
}
}  // namespace

void Robot::inbox() {
    pollfd fds[3] = {{flooder_.fileno(), POLLIN, 0}, {goals_.fileno(), POLLIN, 0},
                     {wake_r_.get(), POLLIN, 0}};
    const double linger = timing_.flood_linger_s();
    while (!stopping) {
        if (poll(fds, 3, 500) <= 0) continue;
        // Copies of a flood arrive in bursts: linger so that one wake-up drains the burst.
        std::this_thread::sleep_for(std::chrono::duration<double>(linger));
        poll(fds, 3, 0);
        std::vector<std::pair<char, std::string>> batch;
        if (fds[0].revents & POLLIN)
            for (auto& d : flooder_.receive_raw()) batch.emplace_back(FLOOD, std::move(d));
        if (fds[1].revents & POLLIN)
            for (auto& d : goals_.receive()) batch.emplace_back(MESSAGE, std::move(d));
        for (auto& item : batch)
            if (!inbox_q_.put(std::move(item))) ++inbox_dropped_;  // stuck: drop, never block
    }
}

void Robot::processing() {
    while (!stopping) {
        std::pair<char, std::string> item;
        if (!inbox_q_.get(item, 0.5)) continue;
        if (item.first == STOP) break;
        std::string err;
        bool ok = item.first == FLOOD ? on_flood(item.second, err) : on_message(item.second, err);
        if (!ok) {
            ++malformed_;
            LOG_WARN("node.robot", "dropped a malformed message: %s", err.c_str());
        }
    }
}

bool Robot::on_flood(const std::string& data, std::string& err) {
    double t_cpu = thread_cpu_s();
    const uint8_t* d = reinterpret_cast<const uint8_t*>(data.data());
    FloodHeader h;
    if (!unpack_flood(d, data.size(), h, err)) return false;
    if ((h.kind != KIND_MAP && h.kind != KIND_BEACON) || h.origin < 1 ||
        h.origin > a_.robots + 1) {
        err = "unexpected flood kind " + std::to_string(h.kind) + " from " +
              std::to_string(h.origin);
        return false;
    }
    // Someone back in reach after a while missed our deltas: send the whole map next.
    int64_t now;
    {
        std::lock_guard<std::mutex> g(lock_);
        now = step_;
    }
    auto last = last_heard_.find(h.origin);
    if (last == last_heard_.end() || now - last->second > REACH_STEPS) full_wanted_ = true;
    last_heard_[h.origin] = now;
    const uint8_t* payload = d + h.payload_at;
    size_t n = data.size() - h.payload_at;
    if (h.kind == KIND_BEACON) {
        double x, y;
        if (!unpack_beacon(payload, n, x, y, err)) return false;
        count(received_, "beacon");
        events_.write("recv", now, JsonObj().str("kind", "beacon").num("frm", h.origin)
                                       .num("seq", h.seq).num("sent", h.step)
                                       .real("t", py_round(monotonic_s(), 4)));
        return true;
    }
    MapMsg m;
    if (!unpack_map(payload, n, a_.rows, a_.cols, m, err)) return false;
    int64_t learnt, step;
    {
        std::lock_guard<std::mutex> g(lock_);
        const int p = laser_.pad;
        learnt = 0;
        if (m.cells.h * m.cells.w != 0) {
            float* at = lp_.data() + static_cast<size_t>(p + m.r0) * stride_ + p + m.c0;
            learnt = sc_merge_ternary(at, stride_, m.cells.cells.data(), m.cells.h, m.cells.w,
                                      THRESHOLD, MERGED);
        }
        auto tm = teammates_.find(h.origin);
        if (tm != teammates_.end()) {
            tm->second.heard = step_;
            tm->second.pos = std::make_pair(m.x, m.y);
        }
        step = step_;
    }
    count(received_, "map");
    events_.write("recv", step, JsonObj().str("kind", "map").num("frm", h.origin)
                                    .num("seq", h.seq).num("sent", h.step).num("ttl", h.ttl)
                                    .num("learnt", learnt).real("t", py_round(monotonic_s(), 4)));
    count(busy_, "merge", thread_cpu_s() - t_cpu);
    return true;
}

bool Robot::on_message(const std::string& data, std::string& err) {
    GoalMsg m;
    if (!parse_msg(data, a_.robots, m, err)) return false;
    int j = m.from;
    if (j == a_.robot) {
        err = "a message claiming to be from myself";
        return false;
    }
    int64_t step;
    std::optional<std::pair<double, double>> mine;
    double my_cost;
    {
        std::lock_guard<std::mutex> g(lock_);
        step = step_;
        Teammate& tm = teammates_.at(j);
        tm.goal = std::make_pair(m.gx, m.gy);
        tm.goal_step = step;
        if (m.k == MsgKind::goal) tm.cost = m.cost;
        if (plan_ && !finished_ && plan_->has_goal) mine = std::make_pair(plan_->gx, plan_->gy);
        my_cost = plan_ ? plan_->cost : 0.0;
    }
    count(received_, msg_kind_name(m.k));
    arrivals_.note(j, m.n, m.step, step);
    events_.write("recv", step, JsonObj().str("kind", msg_kind_name(m.k)).num("frm", j)
                                    .num("sent", m.step)
                                    .real("t", py_round(monotonic_s(), 4)));
    const bool ours = coordination_ == Coordination::ours;
    if (m.k == MsgKind::goal) {
        // coordination.on_goal: the higher priority detects the conflict and asks.
        if (ours && m.fallback) return true;
        if (!mine || !goals_conflict(mine->first, mine->second, m.gx, m.gy, a_.laser_range))
            return true;
        if (higher_priority(my_cost, a_.robot, m.cost, j)) {
            std::string req = replan_msg(a_.robot, step, mine->first, mine->second, ++msg_numbers_);
            send_to(j, "replan", req, step);
        }
    } else {
        // coordination.on_request: "paper" always re-plans; "ours" only for a goal still
        // mine that still conflicts.
        bool replan = !ours || (mine && goals_conflict(mine->first, mine->second, m.gx, m.gy,
                                                       a_.laser_range));
        if (replan) request("request");
        else events_.write("stale_request", step, JsonObj().num("frm", j));
    }
    return true;
}

}  // namespace tb
