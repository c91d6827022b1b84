#include "laser.h"

#include <algorithm>
#include <cmath>

namespace tb {

namespace {
using gen::TABLE_BUDGET_BYTES;
}

Laser::Laser(double max_range_, int n_rays_, double cell_)
    : max_range(max_range_), cell(cell_), step(cell_ / 2.0), n_rays(n_rays_) {
    step32 = static_cast<float>(step);
    n_samples = static_cast<int>(std::floor(max_range / step + 1e-9));
    pad = static_cast<int>(std::ceil(max_range / cell)) + 2;
    window = 2 * pad + 1;
    const double two_pi = 2.0 * M_PI;
    double per_ray = two_pi / n_rays;
    double per_sample = step / cell;
    size_t n = static_cast<size_t>(n_rays) * n_samples;
    dx.resize(n);
    dy.resize(n);
    mark.resize(n);
    std::vector<int64_t> m(n_samples);
    for (int s = 0; s < n_samples; ++s) {
        double rr = static_cast<double>(s + 1) * step;
        double v = std::floor(static_cast<double>(n_rays) * 0.8 * cell / (two_pi * rr));
        v = std::max(1.0, v);
        m[s] = static_cast<int64_t>(std::pow(2.0, std::floor(std::log2(v))));
    }
    for (int k = 0; k < n_rays; ++k) {
        double a = static_cast<double>(k) * per_ray;
        double c = std::cos(a), sn = std::sin(a);
        for (int s = 0; s < n_samples; ++s) {
            double r = static_cast<double>(s + 1) * per_sample;
            size_t i = static_cast<size_t>(k) * n_samples + s;
            dx[i] = static_cast<float>(c * r);
            dy[i] = static_cast<float>(sn * r);
            mark[i] = (k % m[s]) == 0;
            if (mark[i]) {
                mark_dx.push_back(dx[i]);
                mark_dy.push_back(dy[i]);
            }
        }
    }
    tabled = static_cast<int64_t>(BUCKETS) * BUCKETS * window * window <= TABLE_BUDGET_BYTES;
}

MarkTable Laser::build(int bx, int by) const {
    const int size = FRAC / BUCKETS;
    const int base = BIAS + pad + 2;
    size_t n = mark_dx.size();
    auto rel = [&](const std::vector<float>& d, int code, std::vector<int32_t>& out) {
        float add =
            static_cast<float>(static_cast<double>(base) + static_cast<double>(code) / FRAC);
        out.resize(n);
        for (size_t i = 0; i < n; ++i) out[i] = (int32_t)(d[i] + add) - base;
    };
    std::vector<int32_t> col, col1, row, row1;
    rel(mark_dx, bx * size, col);
    rel(mark_dx, (bx + 1) * size - 1, col1);
    rel(mark_dy, by * size, row);
    rel(mark_dy, (by + 1) * size - 1, row1);
    const int w = window;
    const int at = pad * (w + 1);
    MarkTable t;
    t.sure.assign(static_cast<size_t>(w) * w, 0);
    std::vector<uint8_t> sure(n);
    for (size_t i = 0; i < n; ++i) {
        sure[i] = col[i] == col1[i] && row[i] == row1[i];
        if (sure[i]) t.sure[at + row[i] * w + col[i]] = 1;
    }
    for (size_t i = 0; i < n; ++i) {
        if (sure[i]) continue;
        bool covered = t.sure[at + row[i] * w + col[i]] && t.sure[at + row[i] * w + col1[i]] &&
                       t.sure[at + row1[i] * w + col[i]] && t.sure[at + row1[i] * w + col1[i]];
        if (!covered) {
            t.odx.push_back(mark_dx[i]);
            t.ody.push_back(mark_dy[i]);
        }
    }
    return t;
}

void Laser::prepare_tables() {
    if (!tabled || !tables.empty()) return;
    tables.reserve(BUCKETS * BUCKETS);
    for (int bx = 0; bx < BUCKETS; ++bx)
        for (int by = 0; by < BUCKETS; ++by) tables.push_back(build(bx, by));
}

const MarkTable* Laser::table_for(float fx, float fy) const {
    if (!tabled || tables.empty()) return nullptr;
    int cb = static_cast<int>(fx), rb = static_cast<int>(fy);
    int lo = std::min(cb, rb) - pad - 1, hi = std::max(cb, rb) + pad + 1;
    if (!(BIAS <= lo && lo < hi && hi < 2 * BIAS)) return nullptr;
    const int size = FRAC / BUCKETS;
    int bx = static_cast<int>((static_cast<double>(fx) - cb) * FRAC) / size;
    int by = static_cast<int>((static_cast<double>(fy) - rb) * FRAC) / size;
    return &tables[static_cast<size_t>(bx) * BUCKETS + by];
}

}  // namespace tb
