// The robots' and the world's per-step work in compiled code: the laser cast, the scan into
// the map, map classification and merges, and the planner (pool, inflation, frontiers,
// wavefront, path). Each function is the twin of a numpy function named in its comment and
// computes the same result cell for cell: the same float32 and float64 operations in the same
// order (built with -ffp-contract=off, so no fused multiply-add changes a rounding), the same
// tie-breaking order in the wavefront. tests/unit/test_stepcore.py holds the two equal on
// random maps, poses and scans. A plain C ABI, loaded with ctypes (node/stepcore.py): no
// Python headers are needed to build it, only g++.
//
// Arrays are C-contiguous; booleans are one byte, 0 or 1, as numpy stores them.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <vector>

#include "stepcore.h"

namespace {

constexpr uint8_t UNKNOWN = 0, FREE = 1, OCC = 2;

// node.rays: per-ray hit sample from a scan's ranges (Laser.hit_index); float32 arithmetic.
// A range is any float: not finite, nothing hit; else range / step, clamped to [-1, n_samples
// + 1] before it is converted (a range of 1e30 would not fit an int), rounded half to even,
// minus one, clamped to [0, n_samples]. The clamp changes nothing a laser can measure.
inline int32_t hit_index(float range, float step, int n_samples) {
    if (!std::isfinite(range)) return n_samples;
    const float lim = (float)(n_samples + 1);
    float q = range / step;
    q = q < -1.0f ? -1.0f : (q > lim ? lim : q);  // q / step may be inf; never NaN here
    int32_t i = (int32_t)std::nearbyintf(q) - 1;
    return std::min(std::max(i, 0), n_samples);
}

// A float64 as an int in [lo, hi] (lo <= hi): below lo (or NaN) lo, above hi hi, else
// truncated toward zero as C++ and Python's int() do; never converts a value out of range.
inline int clamp_int(double v, int lo, int hi) {
    if (!(v > (double)lo)) return lo;
    if (v >= (double)hi) return hi;
    return (int)v;
}

// World._cast_window's rays: each ray's first sample from s0 on that falls in an obstacle cell
// of the window at `occ` (rows of `stride`), in idx[k] (n_samples: none), and its range in
// ranges[k] (+inf: none; float64 arithmetic, as numpy). True when some ray hit.
bool first_hits(const float* dx, const float* dy, int n_rays, int n_samples, double step,
                float fx, float fy, int roff, int coff, const uint8_t* occ, int64_t stride,
                int s0, float* ranges, int32_t* idx) {
    bool any = false;
    for (int k = 0; k < n_rays; ++k) {
        int first = n_samples;
        const float* rx = dx + (size_t)k * n_samples;
        const float* ry = dy + (size_t)k * n_samples;
        for (int s = s0; s < n_samples; ++s) {
            int64_t r = (int32_t)(ry[s] + fy) + roff;
            int64_t c = (int32_t)(rx[s] + fx) + coff;
            if (occ[r * stride + c]) {
                first = s;
                break;
            }
        }
        idx[k] = first;
        if (first < n_samples) {
            any = true;
            ranges[k] = (float)((double)(first + 1) * step);
        } else {
            ranges[k] = INFINITY;
        }
    }
    return any;
}

// What a cast saw (window_marks): the marked samples before each ray's hit (every marked
// sample when no ray hit) and each hit sample; see(r, c) for each, in window cells.
template <class See>
void each_seen(const float* dx, const float* dy, const uint8_t* mark, int n_rays, int n_samples,
               float fx, float fy, int roff, int coff, bool any, const int32_t* idx, See see) {
    for (int k = 0; k < n_rays; ++k) {
        int lim = any ? idx[k] : n_samples;
        const float* rx = dx + (size_t)k * n_samples;
        const float* ry = dy + (size_t)k * n_samples;
        const uint8_t* mk = mark + (size_t)k * n_samples;
        for (int s = 0; s < lim; ++s)
            if (mk[s]) see((int32_t)(ry[s] + fy) + roff, (int32_t)(rx[s] + fx) + coff);
        if (any && lim < n_samples) {
            size_t a = (size_t)k * n_samples + lim;
            see((int64_t)(dy[a] + fy) + roff, (int64_t)(dx[a] + fx) + coff);
        }
    }
}

}  // namespace

extern "C" {

int sc_version(void) { return 3; }

// Laser.window_marks: the window cells (w x w, row-major) of the marked samples before each
// ray's hit, and each hit sample's cell. idx: per-ray hit sample (n_samples: none) or null for
// a scan without hits. occ_out gets at most n_rays entries; returns their count.
int sc_window_marks(const float* dx, const float* dy, const uint8_t* mark, int n_rays,
                    int n_samples, int w, float fx, float fy, int roff, int coff,
                    const int32_t* idx, uint8_t* free_out, int64_t* occ_out) {
    std::memset(free_out, 0, (size_t)w * w);
    for (int k = 0; k < n_rays; ++k) {
        int lim = idx ? idx[k] : n_samples;
        const float* rx = dx + (size_t)k * n_samples;
        const float* ry = dy + (size_t)k * n_samples;
        const uint8_t* mk = mark + (size_t)k * n_samples;
        for (int s = 0; s < lim; ++s) {
            if (!mk[s]) continue;
            int32_t r = (int32_t)(ry[s] + fy) + roff;
            int32_t c = (int32_t)(rx[s] + fx) + coff;
            free_out[r * w + c] = 1;
        }
    }
    int n = 0;
    if (idx) {
        for (int k = 0; k < n_rays; ++k) {
            int s = idx[k];
            if (s >= n_samples) continue;
            size_t at = (size_t)k * n_samples + s;
            int64_t r = (int64_t)(dy[at] + fy) + roff;
            int64_t c = (int64_t)(dx[at] + fx) + coff;
            occ_out[n++] = r * w + c;
        }
    }
    return n;
}

// Laser.window_marks' table path for a scan without hits: the cells every marked sample
// falls in for any laser position in its sub-cell class (`sure`, a w x w mask), and the few
// samples whose cell depends on the exact position (odx, ody), computed. The result goes into
// the w x w window of `dst` (rows of `stride`): copied (`or_into` 0) or OR-ed in.
void sc_mark_table(const uint8_t* sure, int w, const float* odx, const float* ody, int n_open,
                   float fx, float fy, int roff, int coff, uint8_t* dst, int64_t stride,
                   int or_into) {
    for (int r = 0; r < w; ++r) {
        uint8_t* d = dst + (int64_t)r * stride;
        const uint8_t* s = sure + (size_t)r * w;
        if (or_into) {
            for (int c = 0; c < w; ++c) d[c] |= s[c];
        } else {
            std::memcpy(d, s, w);
        }
    }
    for (int i = 0; i < n_open; ++i) {
        int64_t r = (int32_t)(ody[i] + fy) + roff;
        dst[r * stride + (int32_t)(odx[i] + fx) + coff] = 1;
    }
}

// World._cast_window + window_marks: cast a laser from (fx, fy) (float32 cell coordinates
// plus the bias) on the w x w window at (r0, c0) of the padded obstacle grid, samples s0..
// only; ranges_out gets each ray's range (+inf: none) and the window of `seen` (same shape
// as the obstacle grid, row length `stride`) is marked with what the scan saw. Returns 1 when
// some ray hit, 0 when none did.
int sc_cast_window(const float* dx, const float* dy, const uint8_t* mark, int n_rays,
                   int n_samples, double step, float fx, float fy, int roff, int coff,
                   const uint8_t* occ, uint8_t* seen, int64_t stride, int s0,
                   float* ranges_out, int32_t* idx_tmp) {
    bool any = first_hits(dx, dy, n_rays, n_samples, step, fx, fy, roff, coff, occ, stride, s0,
                          ranges_out, idx_tmp);
    each_seen(dx, dy, mark, n_rays, n_samples, fx, fy, roff, coff, any, idx_tmp,
              [&](int64_t r, int64_t c) { seen[r * stride + c] = 1; });
    return any ? 1 : 0;
}

// testbed.world's casts of one step in one call: World.scan for each robot i with want[i]
// (xy: its x, y; metres), as sc_mark_table and sc_cast_window do them, on the padded obstacle
// grid `occ` (ph x pw) and the cells seen so far `seen` (same shape). The map's cell (r, c)
// under the robot says, through `open_space` and `skip` (mh x mw), which samples can hit.
// tables: per pose-fraction class (buckets x buckets, row bx), the laser's table of a scan
// without hits (sure mask, open dx, open dy, how many open), or tabled = 0 for none.
// Out: ranges_out row i (n_rays) and hit_out[i]: 1 some ray hit (the row holds the ranges),
// 0 none did (the row is not written), -1 nothing done (the window does not fit, or the robot
// is off the map): World.scan's own path takes that robot. Returns how many cells of
// `free_pad` (same shape as `occ`) were seen for the first time, for the coverage count.
int64_t sc_world_cast(int n, const double* xy, const uint8_t* want, double map_cell,
                      double laser_cell, int bias, int pad, int w, const float* dx,
                      const float* dy, const uint8_t* mark, int n_rays, int n_samples,
                      double step, int tabled, int frac, int buckets,
                      const uint8_t* const* sures, const float* const* odxs,
                      const float* const* odys, const int32_t* n_opens, const uint8_t* occ,
                      uint8_t* seen, const uint8_t* free_pad, int64_t ph, int64_t pw,
                      const uint8_t* open_space, const int32_t* skip, int64_t mh, int64_t mw,
                      float* ranges_out, int8_t* hit_out, int32_t* idx_tmp) {
    int64_t fresh = 0;
    const int size = frac / buckets;
    for (int i = 0; i < n; ++i) {
        hit_out[i] = -1;
        if (!want[i]) continue;
        const double x = xy[2 * i], y = xy[2 * i + 1];
        const double mr = y / map_cell, mc = x / map_cell;
        if (!(mr >= 0 && mc >= 0 && mr < (double)mh && mc < (double)mw)) continue;
        const int64_t cell = (int64_t)mr * mw + (int64_t)mc;
        const int s0 = open_space[cell] ? n_samples : std::min(skip[cell], n_samples);
        const float fx = (float)(x / laser_cell + bias), fy = (float)(y / laser_cell + bias);
        const int cb = (int)fx, rb = (int)fy;
        const int64_t r0 = rb - bias, c0 = cb - bias;
        if (r0 < 0 || c0 < 0 || r0 + w > ph || c0 + w > pw) continue;
        const int roff = pad - rb, coff = pad - cb;
        const int64_t at = r0 * pw + c0;
        uint8_t* sn = seen + at;
        const uint8_t* fp = free_pad + at;
        auto see_at = [&](int64_t r, int64_t c) {  // branch-free: new cells are few
            const int64_t k = r * pw + c;
            fresh += (sn[k] ^ 1) & fp[k];
            sn[k] = 1;
        };
        if (s0 >= n_samples && tabled && bias <= std::min(cb, rb) - pad - 1 &&
            std::max(cb, rb) + pad + 1 < 2 * bias) {
            const int key = ((int)(((double)fx - cb) * frac) / size) * buckets +
                            (int)(((double)fy - rb) * frac) / size;
            const uint8_t* sure = sures[key];
            for (int r = 0; r < w; ++r) {
                uint8_t* d = sn + r * pw;
                const uint8_t* f = fp + r * pw;
                const uint8_t* m = sure + (size_t)r * w;
                uint32_t row = 0;  // vectorises: no branch, a byte sum per row
                for (int c = 0; c < w; ++c) {
                    row += (uint8_t)(m[c] & (d[c] ^ 1) & f[c]);
                    d[c] |= m[c];
                }
                fresh += row;
            }
            const float* odx = odxs[key];
            const float* ody = odys[key];
            for (int j = 0; j < n_opens[key]; ++j)
                see_at((int32_t)(ody[j] + fy) + roff, (int32_t)(odx[j] + fx) + coff);
            hit_out[i] = 0;
            continue;
        }
        const bool any = first_hits(dx, dy, n_rays, n_samples, step, fx, fy, roff, coff,
                                    occ + at, pw, s0, ranges_out + (size_t)i * n_rays, idx_tmp);
        each_seen(dx, dy, mark, n_rays, n_samples, fx, fy, roff, coff, any, idx_tmp, see_at);
        hit_out[i] = any ? 1 : 0;
    }
    return fresh;
}

// World.cast_live's step: sc_world_cast (its arguments from n on) for each robot i that is
// live[i] and stands elsewhere than at its last cast (xy row i, which takes its new position),
// from its pose xyt row i (x, y, theta). has_out[i] then says what its frame carries: 1 the
// ranges row, 0 no returns, -1 nothing done (World.scan's own path casts it: *fallbacks_out
// counts those). Returns the free cells seen for the first time, as sc_world_cast.
int64_t sc_world_cast_moved(const double* xyt, const uint8_t* live, int8_t* has_out,
                            int32_t* fallbacks_out, int n, double* xy, uint8_t* want,
                            double map_cell, double laser_cell, int bias, int pad, int w,
                            const float* dx, const float* dy, const uint8_t* mark, int n_rays,
                            int n_samples, double step, int tabled, int frac, int buckets,
                            const uint8_t* const* sures, const float* const* odxs,
                            const float* const* odys, const int32_t* n_opens,
                            const uint8_t* occ, uint8_t* seen, const uint8_t* free_pad,
                            int64_t ph, int64_t pw, const uint8_t* open_space,
                            const int32_t* skip, int64_t mh, int64_t mw, float* ranges_out,
                            int8_t* hit_out, int32_t* idx_tmp) {
    bool any = false;
    for (int i = 0; i < n; ++i) {
        const double x = xyt[3 * i], y = xyt[3 * i + 1];
        want[i] = live[i] && !(x == xy[2 * i] && y == xy[2 * i + 1]);
        if (!want[i]) continue;
        xy[2 * i] = x;
        xy[2 * i + 1] = y;
        any = true;
    }
    *fallbacks_out = 0;
    if (!any) return 0;
    const int64_t fresh = sc_world_cast(n, xy, want, map_cell, laser_cell, bias, pad, w, dx, dy,
                                        mark, n_rays, n_samples, step, tabled, frac, buckets,
                                        sures, odxs, odys, n_opens, occ, seen, free_pad, ph, pw,
                                        open_space, skip, mh, mw, ranges_out, hit_out, idx_tmp);
    for (int i = 0; i < n; ++i) {
        if (!want[i]) continue;
        has_out[i] = hit_out[i];
        if (hit_out[i] < 0) ++*fallbacks_out;
    }
    return fresh;
}

// Robot._put_scan with Laser.scan_window and OccupancyGrid.update_window: one scan into the
// log-odds map `lp` and the ternary local map `own` (both padded, row length `stride`), on
// the window whose top-left cell is (r0, c0). Free cells first (each once), then the hit
// cells (each once, however many rays hit it), as numpy's buffered fancy indexing does.
void sc_scan_into(const float* dx, const float* dy, const uint8_t* mark, int n_rays,
                  int n_samples, float step, int w, float fx, float fy, int roff, int coff,
                  const float* ranges, float* lp, uint8_t* own, int64_t stride, int64_t r0,
                  int64_t c0, float l_free, float l_occ, float l_max, uint8_t* free_tmp,
                  int64_t* occ_tmp, const uint8_t* sure, const float* odx, const float* ody,
                  int n_open) {
    std::vector<int32_t> idx(n_rays);
    bool any = false;
    for (int k = 0; k < n_rays; ++k) {
        idx[k] = hit_index(ranges[k], step, n_samples);
        any = any || std::isfinite(ranges[k]);
    }
    int n_occ = 0;
    if (!any && sure)  // no hits: the laser's table for its sub-cell position
        sc_mark_table(sure, w, odx, ody, n_open, fx, fy, roff, coff, free_tmp, w, 0);
    else
        n_occ = sc_window_marks(dx, dy, mark, n_rays, n_samples, w, fx, fy, roff, coff,
                                any ? idx.data() : nullptr, free_tmp, occ_tmp);
    const float lo = -l_max;
    for (int r = 0; r < w; ++r) {
        float* row = lp + (r0 + r) * stride + c0;
        uint8_t* orow = own + (r0 + r) * stride + c0;
        const uint8_t* fr = free_tmp + (size_t)r * w;
        for (int c = 0; c < w; ++c) {
            if (!fr[c]) continue;
            float v = row[c] + l_free;
            row[c] = v > lo ? v : lo;
            orow[c] = FREE;
        }
    }
    // Hit cells: every new value from the values before any of them was written.
    std::sort(occ_tmp, occ_tmp + n_occ);
    int64_t* end = std::unique(occ_tmp, occ_tmp + n_occ);
    for (int64_t* p = occ_tmp; p != end; ++p) {
        int64_t at = (r0 + *p / w) * stride + c0 + *p % w;
        float v = lp[at] + l_occ;
        lp[at] = v < l_max ? v : l_max;
        own[at] = OCC;
    }
}

// node.grid.classify: UNKNOWN, FREE below -threshold, OCC above +threshold (float32 compares).
// The map may be a strided view: rows of `stride` floats. Branch-free, so it vectorises.
void sc_classify(const float* l, int h, int w, int64_t stride, float threshold, uint8_t* out) {
    const float neg = -threshold;
    for (int r = 0; r < h; ++r) {
        const float* row = l + (int64_t)r * stride;
        uint8_t* o = out + (size_t)r * w;
        for (int c = 0; c < w; ++c) {
            float v = row[c];
            o[c] = (uint8_t)((v < neg) | ((v > threshold) << 1));
        }
    }
}

// OccupancyGrid.merge_ternary: cells unknown here and known in `t` take +-merged; returns how
// many. `l` points at the map's cell (r0, c0); rows of `stride` floats.
int64_t sc_merge_ternary(float* l, int64_t stride, const uint8_t* t, int h, int w,
                         float threshold, float merged) {
    int64_t n = 0;
    for (int r = 0; r < h; ++r) {
        float* row = l + (int64_t)r * stride;
        const uint8_t* tr = t + (size_t)r * w;
        for (int c = 0; c < w; ++c) {
            if (tr[c] != UNKNOWN && std::fabs(row[c]) < threshold) {
                row[c] = tr[c] == FREE ? -merged : merged;
                ++n;
            }
        }
    }
    return n;
}

// World.coverage: cells set in both arrays (0/1 bytes), summed in blocks that vectorise.
int64_t sc_count_and(const uint8_t* a, const uint8_t* b, int64_t n) {
    int64_t k = 0, i = 0;
    while (i < n) {
        int64_t e = std::min(n, i + 8192);
        uint32_t s = 0;
        for (; i < e; ++i) s += (uint8_t)(a[i] & b[i]);
        k += s;
    }
    return k;
}

// node.planner.pool: planning cells of factor x factor map cells (OCC if any, FREE if all).
void sc_pool(const uint8_t* t, int h, int w, int factor, uint8_t* out) {
    int ph = h / factor, pw = w / factor;
    if (factor == 2) {  // the default, branch-free
        for (int r = 0; r < ph; ++r) {
            const uint8_t* a = t + (size_t)(2 * r) * w;
            const uint8_t* b = a + w;
            uint8_t* o = out + (size_t)r * pw;
            for (int c = 0; c < pw; ++c) {
                uint8_t x0 = a[2 * c], x1 = a[2 * c + 1], x2 = b[2 * c], x3 = b[2 * c + 1];
                uint8_t mx = std::max(std::max(x0, x1), std::max(x2, x3));
                uint8_t mn = std::min(std::min(x0, x1), std::min(x2, x3));
                o[c] = mx == OCC ? OCC : (uint8_t)(mn == FREE);
            }
        }
        return;
    }
    for (int r = 0; r < ph; ++r)
        for (int c = 0; c < pw; ++c) {
            uint8_t mx = 0, mn = 255;
            for (int i = 0; i < factor; ++i) {
                const uint8_t* row = t + (size_t)(r * factor + i) * w + c * factor;
                for (int j = 0; j < factor; ++j) {
                    mx = std::max(mx, row[j]);
                    mn = std::min(mn, row[j]);
                }
            }
            out[(size_t)r * pw + c] = mx == OCC ? OCC : (mn == FREE ? FREE : UNKNOWN);
        }
}

// node.planner.dilate of `mask` by a kernel symmetric about its centre that is, row dy of
// 2r + 1, the span |dx| <= half[dy]: each row of the kernel is a horizontal dilation (OR of
// shifted rows), and the rows are OR-ed in at their offsets. Outside counts as false.
static void dilate_spans(const uint8_t* mask, int h, int w, int r, const int* half,
                         uint8_t* out) {
    size_t n = (size_t)h * w;
    std::memset(out, 0, n);
    std::vector<uint8_t> rows(n);
    int done = -1;
    for (int dy = -r; dy <= r; ++dy) {
        int hw = half[dy + r];
        if (hw < 0) continue;
        if (hw != done) {  // rows: the horizontal dilation by hw
            std::memcpy(rows.data(), mask, n);
            for (int d = 1; d <= hw; ++d)
                for (int y = 0; y < h; ++y) {
                    uint8_t* dst = rows.data() + (size_t)y * w;
                    const uint8_t* src = mask + (size_t)y * w;
                    for (int x = 0; x < w - d; ++x) dst[x] |= src[x + d];
                    for (int x = d; x < w; ++x) dst[x] |= src[x - d];
                }
            done = hw;
        }
        int y0 = std::max(0, -dy), y1 = std::min(h, h - dy);
        for (int y = y0; y < y1; ++y) {
            uint8_t* dst = out + (size_t)y * w;
            const uint8_t* src = rows.data() + (size_t)(y + dy) * w;
            for (int x = 0; x < w; ++x) dst[x] |= src[x];
        }
    }
}

// node.planner.traversable: FREE planning cells not within `inflate` cells of an OCC one.
void sc_traversable(const uint8_t* p, int h, int w, int inflate, uint8_t* out) {
    size_t n = (size_t)h * w;
    std::vector<uint8_t> occ(n), grown(n);
    for (size_t i = 0; i < n; ++i) occ[i] = p[i] == OCC;
    if (inflate > 0) {  // node.planner.disc: dy * dy + dx * dx <= inflate * inflate
        std::vector<int> half(2 * inflate + 1);
        for (int dy = -inflate; dy <= inflate; ++dy) {
            int hw = -1;
            while ((hw + 1) * (hw + 1) + dy * dy <= inflate * inflate) ++hw;
            half[dy + inflate] = hw;
        }
        dilate_spans(occ.data(), h, w, inflate, half.data(), grown.data());
    } else {
        grown = occ;
    }
    for (size_t i = 0; i < n; ++i) out[i] = (uint8_t)(p[i] == FREE) & (uint8_t)(grown[i] ^ 1);
}

// node.planner.frontier_goals: traversable cells with an UNKNOWN 8-neighbour.
void sc_frontier_goals(const uint8_t* p, const uint8_t* trav, int h, int w, uint8_t* out) {
    size_t n = (size_t)h * w;
    std::vector<uint8_t> unk(n), near(n);
    for (size_t i = 0; i < n; ++i) unk[i] = p[i] == UNKNOWN;
    static const int half[3] = {1, 1, 1};
    dilate_spans(unk.data(), h, w, 1, half, near.data());
    for (size_t i = 0; i < n; ++i) out[i] = trav[i] & near[i];
}

// node.planner.exclusion_mask: cells whose centre is within `radius` of a goal (OR-ed in).
void sc_exclusion(int h, int w, double plan_cell, const double* goals, int n_goals,
                  double radius, uint8_t* mask) {
    double r = radius / plan_cell;
    for (int g = 0; g < n_goals; ++g) {
        double gc = goals[2 * g] / plan_cell - 0.5, gr = goals[2 * g + 1] / plan_cell - 0.5;
        // Python's max(0, int(floor(..))) and min(h, int(ceil(..)) + 1), clamped before the
        // conversion (a teammate's goal may be any finite number): an empty range stays empty.
        int r0 = clamp_int(std::floor(gr - r), 0, h), r1 = clamp_int(std::ceil(gr + r) + 1, 0, h);
        int c0 = clamp_int(std::floor(gc - r), 0, w), c1 = clamp_int(std::ceil(gc + r) + 1, 0, w);
        for (int y = r0; y < r1; ++y)
            for (int x = c0; x < c1; ++x) {
                double a = (double)y - gr, b = (double)x - gc;
                if (a * a + b * b <= r * r) mask[(size_t)y * w + x] = 1;
            }
    }
}

static void closest(const std::vector<int64_t>& flat, int64_t W, int sr, int sc, int* cell) {
    int64_t best = -1, bd = 0;
    for (int64_t f : flat) {
        int64_t r = f / W - 1, c = f % W - 1;
        int64_t d = (r - sr) * (r - sr) + (c - sc) * (c - sc);
        if (best < 0 || d < bd) {
            best = f;
            bd = d;
        }
    }
    cell[0] = (int)(best / W - 1);
    cell[1] = (int)(best % W - 1);
}

// The wavefront's grid: one byte per cell of the (h + 2) x (w + 2) grid padded by a border
// that is never open, so that a neighbour needs no bounds check. dist is written only where
// REACHED is set.
enum : uint8_t { WF_OPEN = 1, WF_WANT = 2, WF_FALL = 4, WF_REACHED = 8 };

// node.planner.wavefront on the padded grid `f` (see sc_wavefront for the rule). The numpy
// version keeps each ring's candidates in order, each at its last occurrence; here the
// candidates are walked backwards and a cell is taken (closed, given its ring) at its first
// occurrence, which is its last one forwards, so the ring is the same cells in the reverse
// order, and is turned round. Returns 1 "ok", 2 "fallback", 0 "done"; cell_out the goal.
static int wave(uint8_t* f, int32_t* dist, int64_t W, int sr, int sc, int* cell_out) {
    const int64_t s = (int64_t)(sr + 1) * W + sc + 1;
    dist[s] = 0;
    f[s] = (uint8_t)((f[s] & ~WF_OPEN) | WF_REACHED);
    if (f[s] & WF_WANT) {
        cell_out[0] = sr;
        cell_out[1] = sc;
        return 1;
    }
    bool have_fb = f[s] & WF_FALL;
    int fb_cell[2] = {sr, sc};
    const int64_t cross[4] = {-W, W, -1, 1};
    const int64_t diag[4] = {-W - 1, -W + 1, W - 1, W + 1};
    std::vector<int64_t> ring{s}, prev, rev, hit;
    ring.reserve(4096);
    prev.reserve(4096);
    rev.reserve(4096);
    for (int32_t k = 1;; ++k) {
        rev.clear();
        auto take = [&](int64_t q) {
            if (f[q] & WF_OPEN) {
                f[q] = (uint8_t)((f[q] & ~WF_OPEN) | WF_REACHED);
                dist[q] = k;
                rev.push_back(q);
            }
        };
        if (k % 2) {  // forwards: each ring cell's cross neighbours
            for (size_t i = ring.size(); i-- > 0;)
                for (int o = 3; o >= 0; --o) take(ring[i] + cross[o]);
        } else {  // forwards: each ring cell's cross then diagonal ones, then the last ring's
                  // diagonal ones
            for (size_t i = prev.size(); i-- > 0;)
                for (int o = 3; o >= 0; --o) take(prev[i] + diag[o]);
            for (size_t i = ring.size(); i-- > 0;) {
                for (int o = 3; o >= 0; --o) take(ring[i] + diag[o]);
                for (int o = 3; o >= 0; --o) take(ring[i] + cross[o]);
            }
        }
        std::swap(prev, ring);
        ring.assign(rev.rbegin(), rev.rend());
        if (ring.empty()) {
            if (k % 2 && !prev.empty()) continue;
            break;
        }
        hit.clear();
        for (int64_t q : ring)
            if (f[q] & WF_WANT) hit.push_back(q);
        if (!hit.empty()) {
            closest(hit, W, sr, sc, cell_out);
            return 1;
        }
        if (!have_fb) {
            for (int64_t q : ring)
                if (f[q] & WF_FALL) hit.push_back(q);
            if (!hit.empty()) {
                closest(hit, W, sr, sc, fb_cell);
                have_fb = true;
            }
        }
    }
    if (have_fb) {
        cell_out[0] = fb_cell[0];
        cell_out[1] = fb_cell[1];
        return 2;
    }
    return 0;
}

// node.planner.wavefront: rings from (sr, sc) alternating 4- and 8-neighbour growth, in the
// numpy version's order (ring-major candidates, each index kept at its last occurrence), so
// that ties go the same way. dist_out (h x w) gets ring numbers, -1 unreached; cell_out the
// goal cell. Returns 1 "ok", 2 "fallback", 0 "done".
int sc_wavefront(const uint8_t* passable, const uint8_t* wanted, const uint8_t* fallback,
                 int h, int w, int sr, int sc, int32_t* dist_out, int* cell_out) {
    const int64_t W = w + 2, N = (int64_t)(h + 2) * W;
    std::vector<uint8_t> f(N, 0);
    for (int r = 0; r < h; ++r)
        for (int c = 0; c < w; ++c) {
            int64_t j = (int64_t)r * w + c;
            f[(r + 1) * W + c + 1] = (uint8_t)((passable[j] ? WF_OPEN : 0) |
                                               (wanted[j] ? WF_WANT : 0) |
                                               (fallback[j] ? WF_FALL : 0));
        }
    std::unique_ptr<int32_t[]> dist(new int32_t[N]);
    int kind = wave(f.data(), dist.get(), W, sr, sc, cell_out);
    for (int r = 0; r < h; ++r)
        for (int c = 0; c < w; ++c) {
            int64_t i = (int64_t)(r + 1) * W + c + 1;
            dist_out[(int64_t)r * w + c] = f[i] & WF_REACHED ? dist[i] : -1;
        }
    return kind;
}

// node.planner.trace_back on the padded grid: from the goal to the neighbour nearest the
// start (the first of the least, in the order below), until ring 0. Returns the (row, col)
// pairs from the start to the goal.
static std::vector<int> trace(const uint8_t* f, const int32_t* dist, int64_t W, int gr, int gc) {
    const int64_t nb[8] = {-W, W, -1, 1, -W - 1, -W + 1, W - 1, W + 1};
    int64_t q = (int64_t)(gr + 1) * W + gc + 1;
    int32_t d = dist[q];
    std::vector<int64_t> back{q};
    back.reserve((size_t)d + 1);  // each move lowers the ring number
    while (d > 0) {
        int64_t best = -1;
        int32_t bd = d;
        for (int64_t o : nb) {
            int64_t qq = q + o;
            if ((f[qq] & WF_REACHED) && dist[qq] < bd) {
                best = qq;
                bd = dist[qq];
            }
        }
        if (best < 0) break;
        q = best;
        d = bd;
        back.push_back(q);
    }
    std::vector<int> path(2 * back.size());
    for (size_t i = 0; i < back.size(); ++i) {
        int64_t b = back[back.size() - 1 - i];
        path[2 * i] = (int)(b / W - 1);
        path[2 * i + 1] = (int)(b % W - 1);
    }
    return path;
}

// node.planner.line_clear: np.linspace's float64 samples (i * step + start, the last one
// exactly the end), rounded half to even as np.rint does.
static double lin(int a, int b, int n, int i) {
    if (n == 1) return (double)a;
    if (i == n - 1) return (double)b;
    double delta = (double)b - (double)a, div = n - 1, step = delta / div;
    double y = (double)i;
    if (step == 0) {
        y /= div;
        y *= delta;
    } else {
        y *= step;
    }
    return y + (double)a;
}

static bool line_clear(const uint8_t* ok, int w, const int* a, const int* b) {
    int n = 2 * std::max(std::abs(b[0] - a[0]), std::abs(b[1] - a[1])) + 1;
    for (int i = 0; i < n; ++i) {
        int64_t r = (int64_t)std::nearbyint(lin(a[0], b[0], n, i));
        int64_t c = (int64_t)std::nearbyint(lin(a[1], b[1], n, i));
        if (!ok[r * w + c]) return false;
    }
    return true;
}

// node.planner.smooth: greedy string pulling, doubling then bisection from each anchor.
int sc_smooth(const int* cells, int n, const uint8_t* ok, int w, int* out) {
    if (n <= 2) {
        std::memcpy(out, cells, sizeof(int) * 2 * n);
        return n;
    }
    int m = 0;
    out[m * 2] = cells[0];
    out[m * 2 + 1] = cells[1];
    ++m;
    int i = 0;
    while (i < n - 1) {
        int step = 1, good = i + 1;
        while (good + step < n && line_clear(ok, w, cells + 2 * i, cells + 2 * (good + step))) {
            good += step;
            step *= 2;
        }
        int lo = good, hi = std::min(good + step, n);
        while (hi - lo > 1) {
            int mid = (lo + hi) / 2;
            if (line_clear(ok, w, cells + 2 * i, cells + 2 * mid))
                lo = mid;
            else
                hi = mid;
        }
        out[m * 2] = cells[2 * lo];
        out[m * 2 + 1] = cells[2 * lo + 1];
        ++m;
        i = lo;
    }
    return m;
}

// node.planner.plan after the ternary map: pool, traversable, the start cell's neighbourhood
// made passable, frontier goals, the exclusion of teammates' goals, the wavefront, the path
// and its smoothing. status_out: 0 "done", 1 "ok", 2 "fallback", 3 "blocked". path_out gets
// the smoothed cells (row, col), at most max_n of them; returns their count (negative: the
// buffer was too small, by that many).
int sc_plan(const uint8_t* t, int th, int tw, int factor, int inflate, double px, double py,
            double plan_cell, const double* goals, int n_goals, double radius, int fallback_ok,
            int* status_out, int* path_out, int max_n) {
    int h = th / factor, w = tw / factor;
    size_t n = (size_t)h * w;
    std::vector<uint8_t> p(n), trav(n), pass, goalm(n), excl(n, 0);
    sc_pool(t, th, tw, factor, p.data());
    int sr = clamp_int(py / plan_cell, 0, h - 1);  // min(max(int(..), 0), h - 1), defined
    int sc = clamp_int(px / plan_cell, 0, w - 1);
    sc_traversable(p.data(), h, w, inflate, trav.data());
    pass = trav;
    int rr = inflate + 1;
    int r0 = std::max(sr - rr, 0), r1 = std::min(sr + rr + 1, h);
    int c0 = std::max(sc - rr, 0), c1 = std::min(sc + rr + 1, w);
    for (int y = r0; y < r1; ++y)
        for (int x = c0; x < c1; ++x)
            if ((y - sr) * (y - sr) + (x - sc) * (x - sc) <= rr * rr && p[(size_t)y * w + x] == FREE)
                pass[(size_t)y * w + x] = 1;
    pass[(size_t)sr * w + sc] = 1;
    sc_frontier_goals(p.data(), trav.data(), h, w, goalm.data());
    bool any = false;
    for (size_t i = 0; i < n && !any; ++i) any = goalm[i];
    *status_out = 0;
    if (!any) return 0;
    sc_exclusion(h, w, plan_cell, goals, n_goals, radius, excl.data());
    const int64_t W = w + 2, N = (int64_t)(h + 2) * W;
    std::vector<uint8_t> f(N, 0);
    for (int r = 0; r < h; ++r) {
        const size_t j0 = (size_t)r * w;
        uint8_t* fr = f.data() + (r + 1) * W + 1;
        for (int c = 0; c < w; ++c) {
            const size_t j = j0 + c;
            fr[c] = (uint8_t)(pass[j] | (goalm[j] & (uint8_t)!excl[j]) << 1 | goalm[j] << 2);
        }
    }
    std::unique_ptr<int32_t[]> dist(new int32_t[N]);
    int cell[2];
    int kind = wave(f.data(), dist.get(), W, sr, sc, cell);
    if (kind == 0) return 0;
    if (kind == 2 && !fallback_ok) {
        *status_out = 3;
        return 0;
    }
    *status_out = kind;
    std::vector<int> raw = trace(f.data(), dist.get(), W, cell[0], cell[1]);
    int m = (int)raw.size() / 2;
    std::vector<int> sm(2 * (size_t)m);
    int k = sc_smooth(raw.data(), m, pass.data(), w, sm.data());
    if (k > max_n) return -k;
    std::memcpy(path_out, sm.data(), sizeof(int) * 2 * k);
    return k;
}

}  // extern "C"
