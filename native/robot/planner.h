// The planner (node/planner.py's plan): the step core's sc_plan on a ternary snapshot, then
// the waypoints (cell centres) and the path's length as numpy sums it. Pure: no threads.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace tb {

// What a plan found (node.planner.Plan.status): the step core's sc_plan codes, in order.
enum class PlanStatus { done, ok, fallback, blocked };
const char* plan_status_name(PlanStatus s);  // "done", "ok", "fallback", "blocked"

struct Plan {
    PlanStatus status = PlanStatus::done;
    bool has_goal = false;
    double gx = 0, gy = 0;
    std::vector<std::pair<double, double>> path;
    double cost = 0;  // metres
};

struct PlannerParams {
    double cell = 0.05;
    int factor = 2;
    double robot_radius = 0.15;
    double plan_cell() const { return cell * factor; }
    int inflate_cells() const;
};

Plan plan(const std::vector<uint8_t>& t, int rows, int cols, double px, double py,
          const std::vector<std::pair<double, double>>& goals, double exclusion_radius,
          const PlannerParams& prm, bool fallback);

// numpy's pairwise summation of float64 (np.add.reduce), so sums round as numpy's do.
double numpy_sum(const double* a, size_t n);

bool goals_conflict(double ax, double ay, double bx, double by, double laser_range);

}  // namespace tb
