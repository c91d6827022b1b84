// The laser's tabulated geometry (node/rays.py's Laser): each ray's sample offsets, the
// samples that mark cells, and the pose-fraction tables of a scan without hits. Built here
// with the same float64 and float32 operations as numpy builds them (tests/unit hold the
// two equal byte for byte); the per-scan work itself is the step core's (sc_scan_into).
#pragma once

#include <cstdint>
#include <vector>

#include "node_args.h"
#include "robot_consts.h"

namespace tb {

using gen::BIAS;  // node.rays._BIAS
using gen::BUCKETS;
using gen::FRAC;
using gen::MAX_RANGE_M;  // node.rays.MAX_RANGE_M: the longest laser of a run

struct MarkTable {
    std::vector<uint8_t> sure;     // window x window
    std::vector<float> odx, ody;   // the open samples
};

class Laser {
public:
    Laser(double max_range, int n_rays, double cell);
    double max_range, cell, step;
    float step32;
    int n_rays, n_samples, pad, window;
    bool tabled;
    std::vector<float> dx, dy;     // n_rays x n_samples
    std::vector<uint8_t> mark;     // n_rays x n_samples
    std::vector<float> mark_dx, mark_dy;
    std::vector<MarkTable> tables; // BUCKETS x BUCKETS, bx major; built by prepare_tables
    void prepare_tables();
    // The table for a scan from float32 cell coordinates (fx, fy), or null where
    // window_marks would not use one.
    const MarkTable* table_for(float fx, float fy) const;

private:
    MarkTable build(int bx, int by) const;
};

}  // namespace tb
