#include "planner.h"

#include <cmath>
#include <stdexcept>
#include <string>

#include "../stepcore/stepcore.h"

namespace tb {

int PlannerParams::inflate_cells() const {
    return static_cast<int>(std::ceil(robot_radius / plan_cell() - 1e-9));
}

double numpy_sum(const double* a, size_t n) {
    // numpy/core/src/umath/loops_utils.h pairwise_sum: 8 accumulators below 128, halves above.
    if (n < 8) {
        double res = 0.;
        for (size_t i = 0; i < n; ++i) res += a[i];
        return res;
    }
    if (n <= 128) {
        double r[8];
        for (int k = 0; k < 8; ++k) r[k] = a[k];
        size_t i;
        for (i = 8; i < n - (n % 8); i += 8)
            for (int k = 0; k < 8; ++k) r[k] += a[i + k];
        double res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        for (; i < n; ++i) res += a[i];
        return res;
    }
    size_t n2 = n / 2;
    n2 -= n2 % 8;
    return numpy_sum(a, n2) + numpy_sum(a + n2, n - n2);
}

const char* plan_status_name(PlanStatus s) {
    switch (s) {
        case PlanStatus::done: return "done";
        case PlanStatus::ok: return "ok";
        case PlanStatus::fallback: return "fallback";
        case PlanStatus::blocked: return "blocked";
    }
    return "?";
}

Plan plan(const std::vector<uint8_t>& t, int rows, int cols, double px, double py,
          const std::vector<std::pair<double, double>>& goals, double exclusion_radius,
          const PlannerParams& prm, bool fallback) {
    std::vector<double> g;
    for (const auto& p : goals) {
        g.push_back(p.first);
        g.push_back(p.second);
    }
    double pc = prm.plan_cell();
    int status = 0, cap = 256;
    std::vector<int> cells;
    int n;
    while (true) {
        cells.resize(2 * static_cast<size_t>(cap));
        n = sc_plan(t.data(), rows, cols, prm.factor, prm.inflate_cells(), px, py, pc,
                    g.empty() ? nullptr : g.data(), static_cast<int>(goals.size()),
                    exclusion_radius,
                    fallback ? 1 : 0, &status, cells.data(), cap);
        if (n >= 0) break;
        cap = -n;
    }
    Plan out;
    if (status < 0 || status > static_cast<int>(PlanStatus::blocked))
        throw std::runtime_error("the step core's planner gave status " + std::to_string(status));
    out.status = static_cast<PlanStatus>(status);
    if (n == 0) return out;
    for (int i = 0; i < n; ++i) {
        int r = cells[2 * i], c = cells[2 * i + 1];
        out.path.emplace_back((c + 0.5) * pc, (r + 0.5) * pc);
    }
    out.has_goal = true;
    out.gx = out.path.back().first;
    out.gy = out.path.back().second;
    // path_length: np.hypot of the cell differences, summed, times the plan cell.
    std::vector<double> seg;
    for (int i = 1; i < n; ++i)
        seg.push_back(std::hypot(static_cast<double>(cells[2 * i] - cells[2 * i - 2]),
                                 static_cast<double>(cells[2 * i + 1] - cells[2 * i - 1])));
    out.cost = n < 2 ? 0.0 : numpy_sum(seg.data(), seg.size()) * pc;
    return out;
}

bool goals_conflict(double ax, double ay, double bx, double by, double laser_range) {
    return std::hypot(ax - bx, ay - by) <= laser_range;
}

}  // namespace tb
