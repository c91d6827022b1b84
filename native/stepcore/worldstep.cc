// The world's step in compiled code: what testbed.run.steploop's Python loop does each step
// between the deadline and the links, in a few calls instead of a dozen Python calls a robot.
//
// - sc_sleep_until: the deadline's sleep (CLOCK_MONOTONIC, absolute: time.sleep and
//   time.monotonic's clock). A signal ends it early, so that Python's handlers run (Ctrl-C);
//   the caller sleeps again while the deadline is ahead.
// - sc_step_take: StepLoop._take_commands and the deadline count of _collect_commands. Every
//   command waiting on the body links is taken (sc_body_take), each robot's last target into
//   its body (World.command) and its largest step into its record (RobotRecord.answered);
//   the robots still in the run that had not answered the step's frame are counted and their
//   steps kept (RobotRecord.missed_deadline). The datagrams that are not commands (a "done",
//   a HELLO) and the sockets that hung up stay for Python, as sc_body_take leaves them. It
//   also looks, without waiting, whether a fork server has something to say (an exit report):
//   only then does Python look for crashed robots.
// - sc_world_move: World.move, every live robot toward its target, byte for byte: the same
//   float64 operations in the same order (built with -ffp-contract=off), math.hypot as
//   CPython computes it (its vector_norm, not libm's hypot), math.atan2 as CPython wraps it,
//   Python's min() and int() where the Python uses them. A target that is not finite moves
//   no one (as in World.move); a position that is not finite (the world never makes one) is
//   left to World.move itself (nothing is done: it returns 1).
// - sc_world_cast_step: stepcore.cc's sc_world_cast_moved (World.cast_live), its arguments in
//   one struct, and each ray's first hit and the cells it saw found in one pass over its
//   samples (sc_world_cast's first_hits, then each_seen, walk them twice): the same ranges,
//   the same cells seen, the same count of cells seen for the first time.
// - sc_links_spend and sc_links_measure: topology.radio.slack's Slack, kept by the world so
//   that the topology controller is given the positions only when a link can have come or
//   gone: the least gap between any pair's distance and the radio range (less a micrometre),
//   measured where the controller last took the positions, is spent by the two largest moves
//   of each step (each counted a part in 1e9 long); while some is left, no pair can have
//   crossed the range (the triangle inequality) and the links are the ones the controller
//   has. Only where links follow the positions alone (the disc model on veth links).
//
// testbed/world/stepfast.py fills the struct (worldstep.h) with the world's arrays and calls
// these; tests/unit/test_step_fast.py holds each equal to its Python twin.

#include "worldstep.h"

#include <poll.h>
#include <time.h>

#include <algorithm>
#include <cfloat>
#include <cerrno>
#include <cmath>
#include <cstdint>

#include "stepcore.h"

namespace {

struct DoubleLength {
    double hi, lo;
};

// CPython's dl_fast_sum and dl_mul (Modules/mathmodule.c): error-free sum (|a| >= |b|) and
// product.
inline DoubleLength dl_fast_sum(double a, double b) {
    const double x = a + b;
    const double y = (a - x) + b;
    return {x, y};
}

inline DoubleLength dl_mul(double x, double y) {
    const double z = x * y;
    const double zz = std::fma(x, y, -z);
    return {z, zz};
}

// How this machine's Python takes subnormal lengths (sc_py_hypot_mode, set by
// testbed/world/stepfast.py to whichever of the two gives math.hypot's answers): 0 as
// Debian 12's CPython 3.11, dividing by the larger; 1 as later ones, through DBL_MIN.
int g_subnormal_by_dbl_min = 0;

// CPython's vector_norm for two coordinates, given their absolute values and the larger.
double vector_norm2(double a, double b, double max) {
    if (std::isinf(max)) return max;
    if (std::isnan(a) || std::isnan(b)) return NAN;
    if (max == 0.0) return max;
    int max_e;
    std::frexp(max, &max_e);
    if (max_e < -1023 && g_subnormal_by_dbl_min) {  // ldexp(1.0, -max_e) would overflow:
        // later CPythons make the subnormals normal (an exact division), then scale back
        return DBL_MIN * vector_norm2(a / DBL_MIN, b / DBL_MIN, max / DBL_MIN);
    }
    if (max_e < -1023) {  // ldexp(1.0, -max_e) would overflow: CPython 3.11 divides by max
        double csum = 1.0, frac = 0.0;
        const double v[2] = {a, b};
        for (double x : v) {
            x /= max;
            x = x * x;
            const double old = csum;
            csum += x;
            frac += (old - csum) + x;
        }
        return max * std::sqrt(csum - 1.0 + frac);
    }
    const double scale = std::ldexp(1.0, -max_e);
    double csum = 1.0, frac1 = 0.0, frac2 = 0.0;
    const double v[2] = {a, b};
    DoubleLength pr, sm;
    for (double x : v) {
        x *= scale;            // lossless scaling
        pr = dl_mul(x, x);     // lossless squaring
        sm = dl_fast_sum(csum, pr.hi);
        csum = sm.hi;
        frac1 += pr.lo;
        frac2 += sm.lo;
    }
    double h = std::sqrt(csum - 1.0 + (frac1 + frac2));
    pr = dl_mul(-h, h);
    sm = dl_fast_sum(csum, pr.hi);
    csum = sm.hi;
    frac1 += pr.lo;
    frac2 += sm.lo;
    const double x = csum - 1.0 + (frac1 + frac2);
    h += x / (2.0 * h);  // differential correction
    return h / scale;
}

// math.hypot(x, y).
inline double py_hypot(double x, double y) {
    const double a = std::fabs(x), b = std::fabs(y);
    double max = 0.0;
    if (a > max) max = a;
    if (b > max) max = b;
    return vector_norm2(a, b, max);
}

// math.atan2(y, x): CPython's m_atan2 before libm's atan2.
inline double py_atan2(double y, double x) {
    if (std::isnan(x) || std::isnan(y)) return NAN;
    if (std::isinf(y)) {
        if (std::isinf(x)) {
            if (std::copysign(1.0, x) == 1.0) return std::copysign(0.25 * M_PI, y);
            return std::copysign(0.75 * M_PI, y);
        }
        return std::copysign(0.5 * M_PI, y);
    }
    if (std::isinf(x) || y == 0.0) {
        if (std::copysign(1.0, x) == 1.0) return std::copysign(0.0, y);
        return std::copysign(M_PI, y);
    }
    return std::atan2(y, x);
}

// Python's min(a, b) of two floats: b only when b < a.
inline double py_min(double a, double b) { return b < a ? b : a; }

// World._free: the robot's centre may be at (x, y). int() truncates toward zero: a
// coordinate in (-1, 0) cells is in row or column 0, as in the Python.
inline bool world_free(const sc_world_step* s, double x, double y) {
    const double qr = y / s->cell, qc = x / s->cell;
    if (!(qr > -1.0 && qr < (double)s->bh && qc > -1.0 && qc < (double)s->bw)) return false;
    const int64_t r = (int64_t)qr, c = (int64_t)qc;
    return !s->blocked[r * s->bw + c];
}

constexpr int64_t BLOCK = 16;  // samples whose cells sc_world_cast_step computes at once

inline double seconds(const struct timespec& t) {
    // time.monotonic(): the nanoseconds as one integer, then a float divided by 1e9.
    const int64_t ns = (int64_t)t.tv_sec * 1000000000 + (int64_t)t.tv_nsec;
    return (double)ns / 1e9;
}

}  // namespace

extern "C" {

double sc_py_hypot(double x, double y) { return py_hypot(x, y); }
void sc_py_hypot_mode(int64_t by_dbl_min) { g_subnormal_by_dbl_min = by_dbl_min != 0; }

double sc_py_atan2(double y, double x) { return py_atan2(y, x); }

double sc_monotonic(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return seconds(t);
}

// Sleep until CLOCK_MONOTONIC reads `deadline` (seconds; at once if it is past or not a number
// a clock can reach); returns the clock then. A signal ends the sleep early: the caller sees a
// time before the deadline and calls again once Python had its say.
double sc_sleep_until(double deadline) {
    const double now = sc_monotonic();
    if (!(deadline > now) || deadline > 9.0e9) return now;
    struct timespec t;
    const double whole = std::floor(deadline);
    t.tv_sec = (time_t)whole;
    t.tv_nsec = (long)((deadline - whole) * 1e9);
    if (t.tv_nsec >= 1000000000) t.tv_nsec = 999999999;
    if (t.tv_nsec < 0) t.tv_nsec = 0;
    clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &t, nullptr);
    return sc_monotonic();
}

// The step's commands and deadline count (see the top of this file): take what waits on the
// sockets; for robot i (socket i < n) with commands, its last target into its body and its
// largest step into last_cmd. With count_missed, each live robot whose last_cmd is before
// `step` missed the step's deadline. Then a look at the watched descriptors. Returns
// s->others_used (sc_body_take's return: the bytes of other datagrams, negative when it
// stopped early).
int64_t sc_step_take(sc_world_step* s, int64_t step, int64_t count_missed) {
    s->others_used = sc_body_take((int)s->m, s->fds, s->taken, s->steps, s->go, s->xy, s->hung,
                                  s->others, s->others_cap, s->counts);
    if (s->counts[0] > 0) {
        const int64_t robots = s->n < s->m ? s->n : s->m;
        for (int64_t i = 0; i < robots; ++i) {
            if (!s->taken[i]) continue;
            if (s->steps[i] > s->last_cmd[i]) s->last_cmd[i] = s->steps[i];
            s->has_target[i] = s->go[i] ? 1 : 0;
            s->target[2 * i] = s->go[i] ? s->xy[2 * i] : 0.0;
            s->target[2 * i + 1] = s->go[i] ? s->xy[2 * i + 1] : 0.0;
        }
    }
    s->missed_now = 0;
    if (count_missed) {
        for (int64_t i = 0; i < s->n; ++i) {
            if (!s->live[i] || s->last_cmd[i] >= step) continue;
            ++s->missed[i];
            if (s->missed_len[i] < s->missed_cap)
                s->missed_steps[i * s->missed_cap + s->missed_len[i]++] = step;
            ++s->missed_now;
        }
    }
    s->watch_ready = 0;
    for (int64_t j = 0; j < s->n_watch; ++j) {
        struct pollfd p = {s->watch_fds[j], POLLIN, 0};
        int got;
        do {
            got = poll(&p, 1, 0);
        } while (got < 0 && errno == EINTR);
        if (got != 0) {  // readable, hung up, failed, or poll itself failed: Python looks
            s->watch_ready = 1;
            break;
        }
    }
    return s->others_used;
}

// World.move (see the top of this file). Returns 0, or 1 with nothing done when a live robot
// with a target stands somewhere not finite, or the move log is full (World.move's own path).
int64_t sc_world_move(sc_world_step* s) {
    for (int64_t i = 0; i < s->n; ++i) {
        if (!s->alive[i] || !s->has_target[i]) continue;
        const double* p = s->xyt + 3 * i;
        if (!(std::isfinite(p[0]) && std::isfinite(p[1]))) return 1;
    }
    if (s->log_len + s->n > s->log_cap) return 1;  // no room to log the moves: Python's path
    for (int64_t i = 0; i < s->n; ++i) {
        if (!s->alive[i] || !s->has_target[i]) continue;
        double* p = s->xyt + 3 * i;
        const double* t = s->target + 2 * i;
        if (!(std::isfinite(t[0]) && std::isfinite(t[1]))) continue;  // no way leads there
        const double bx = p[0], by = p[1];
        const double dx = s->target[2 * i] - bx, dy = s->target[2 * i + 1] - by;
        const double d = py_hypot(dx, dy);
        if (d < 1e-9) continue;
        const double sp = py_min(s->speed, d);
        const double ux = dx / d, uy = dy / d;
        // Straight on; else slide along an axis; else stay (a collision).
        const double cand[3][2] = {
            {ux, uy}, {std::copysign(1.0, ux), 0.0}, {0.0, std::copysign(1.0, uy)}};
        double mx = 0.0, my = 0.0, nx = 0.0, ny = 0.0;
        bool found = false;
        for (int k = 0; k < 3; ++k) {
            mx = cand[k][0];
            my = cand[k][1];
            if (mx * ux + my * uy <= 1e-6) continue;
            const bool straight = k == 0 || (mx == ux && my == uy);
            const double step_len = straight ? sp : py_min(sp, std::fabs(mx * dx + my * dy));
            nx = bx + mx * step_len;
            ny = by + my * step_len;
            if (world_free(s, nx, ny)) {
                found = true;
                break;
            }
        }
        if (!found) {
            ++s->collisions[i];
            continue;
        }
        if (!(mx == ux && my == uy)) ++s->collisions[i];
        const double moved = py_hypot(nx - bx, ny - by);
        p[2] = py_atan2(dy, dx);
        s->path_length[i] += moved;
        p[0] = nx;
        p[1] = ny;
        s->log_i[s->log_len] = i;
        s->log_xy[2 * s->log_len] = nx;
        s->log_xy[2 * s->log_len + 1] = ny;
        ++s->log_len;
    }
    return 0;
}

// World.cast_live's casts (see the top of this file; stepcore.cc's sc_world_cast_moved and
// sc_world_cast say what each field means). Returns the cells of free_pad seen for the first
// time; p->fallbacks counts the robots it did nothing for (has_out -1).
int64_t sc_world_cast_step(sc_cast_pack* p, const uint8_t* live) {
    const int64_t n = p->n, n_rays = p->n_rays, n_samples = p->n_samples, pw = p->pw;
    const int64_t w = p->w, bias = p->bias, pad = p->pad;
    p->fallbacks = 0;
    bool moved = false;
    for (int64_t i = 0; i < n; ++i) {
        const double x = p->xyt[3 * i], y = p->xyt[3 * i + 1];
        p->want[i] = live[i] && !(x == p->xy[2 * i] && y == p->xy[2 * i + 1]);
        if (!p->want[i]) continue;
        p->xy[2 * i] = x;
        p->xy[2 * i + 1] = y;
        moved = true;
    }
    if (!moved) return 0;
    int64_t fresh = 0;
    const int64_t size = p->frac / p->buckets;
    for (int64_t i = 0; i < n; ++i) {
        p->hit_out[i] = -1;
        if (!p->want[i]) continue;
        const double x = p->xy[2 * i], y = p->xy[2 * i + 1];
        const double mr = y / p->map_cell, mc = x / p->map_cell;
        if (!(mr >= 0 && mc >= 0 && mr < (double)p->mh && mc < (double)p->mw)) {
            p->has_out[i] = -1;
            ++p->fallbacks;
            continue;
        }
        const int64_t cell = (int64_t)mr * p->mw + (int64_t)mc;
        const int64_t s0 = p->open_space[cell] ? n_samples
                                               : std::min<int64_t>(p->skip[cell], n_samples);
        const float fx = (float)(x / p->laser_cell + (int)bias);
        const float fy = (float)(y / p->laser_cell + (int)bias);
        const int cb = (int)fx, rb = (int)fy;
        const int64_t r0 = rb - bias, c0 = cb - bias;
        if (r0 < 0 || c0 < 0 || r0 + w > p->ph || c0 + w > pw) {
            p->has_out[i] = -1;
            ++p->fallbacks;
            continue;
        }
        const int roff = (int)(pad - rb), coff = (int)(pad - cb);
        const int64_t at = r0 * pw + c0;
        uint8_t* sn = p->seen + at;
        const uint8_t* fp = p->free_pad + at;
        auto see_cell = [&](int64_t k) {  // branch-free: new cells are few
            fresh += (sn[k] ^ 1) & fp[k];
            sn[k] = 1;
        };
        auto see_at = [&](int64_t r, int64_t c) { see_cell(r * pw + c); };
        if (s0 >= n_samples && p->tabled && bias <= std::min(cb, rb) - pad - 1 &&
            std::max(cb, rb) + pad + 1 < 2 * bias) {
            const int64_t key = ((int)(((double)fx - cb) * p->frac) / size) * p->buckets +
                                (int)(((double)fy - rb) * p->frac) / size;
            const uint8_t* sure = p->sures[key];
            for (int64_t r = 0; r < w; ++r) {
                uint8_t* d = sn + r * pw;
                const uint8_t* f = fp + r * pw;
                const uint8_t* m = sure + (size_t)(r * w);
                uint32_t row = 0;  // vectorises: no branch, a byte sum per row
                for (int64_t c = 0; c < w; ++c) {
                    row += (uint8_t)(m[c] & (d[c] ^ 1) & f[c]);
                    d[c] |= m[c];
                }
                fresh += row;
            }
            const float* odx = p->odxs[key];
            const float* ody = p->odys[key];
            for (int j = 0; j < p->n_opens[key]; ++j)
                see_at((int32_t)(ody[j] + fy) + roff, (int32_t)(odx[j] + fx) + coff);
            p->hit_out[i] = 0;
            p->has_out[i] = 0;
            continue;
        }
        const uint8_t* oc = p->occ + at;
        float* rg = p->ranges_out + (size_t)(i * n_rays);
        bool any = false;
        for (int64_t k = 0; k < n_rays; ++k) {
            const float* rx = p->dx + (size_t)(k * n_samples);
            const float* ry = p->dy + (size_t)(k * n_samples);
            const uint8_t* mk = p->mark + (size_t)(k * n_samples);
            int64_t first = n_samples;
            // Each block's cells first (a loop the compiler vectorises), then its samples in
            // order: known free before s0 (only what the ray saw), else until the first hit.
            for (int64_t b = 0; b < n_samples && first == n_samples; b += BLOCK) {
                const int64_t e = std::min<int64_t>(b + BLOCK, n_samples);
                int32_t at_cell[BLOCK];
                for (int64_t s = b; s < e; ++s)
                    at_cell[s - b] = ((int32_t)(ry[s] + fy) + roff) * (int32_t)pw +
                                     (int32_t)(rx[s] + fx) + coff;
                for (int64_t s = b; s < e; ++s) {
                    const int64_t cell = at_cell[s - b];
                    if (s >= s0 && oc[cell]) {
                        first = s;
                        see_cell(cell);
                        break;
                    }
                    if (mk[s]) see_cell(cell);
                }
            }
            if (first < n_samples) {
                any = true;
                rg[k] = (float)((double)(first + 1) * p->step);
            } else {
                rg[k] = INFINITY;
            }
        }
        p->hit_out[i] = any ? 1 : 0;
        p->has_out[i] = p->hit_out[i];
    }
    return fresh;
}

// Spend the moves since the positions the controller last took (link_xy's robots; the display
// never moves). Returns 1 when the controller must be given the positions (a link may have
// come or gone, or the slack does not apply), 0 when the links are the ones it has.
int64_t sc_links_spend(sc_world_step* s) {
    if (!s->links_slack || !(s->slack_left >= 0.0)) return 1;
    double first = 0.0, second = 0.0;
    for (int64_t i = 0; i < s->n; ++i) {
        const double* p = s->xyt + 3 * i;
        double* l = s->link_xy + 2 * i;
        const double d = py_hypot(p[0] - l[0], p[1] - l[1]);
        if (d > first) {
            second = first;
            first = d;
        } else if (d > second) {
            second = d;
        }
        l[0] = p[0];
        l[1] = p[1];
    }
    s->slack_left -= (first + second) * (1.0 + 1e-9);
    if (s->slack_left > 0.0) return 0;
    s->slack_left = -1.0;
    return 1;
}

// The controller just took the robots' positions (xyt) and the display's (link_xy row n): the
// links are the range model's there. The least gap of any pair's distance from the range, less
// a micrometre, is the slack from here (infinite for fewer than two; not a number: none).
void sc_links_measure(sc_world_step* s) {
    const int64_t m = s->n + 1;
    for (int64_t i = 0; i < s->n; ++i) {
        s->link_xy[2 * i] = s->xyt[3 * i];
        s->link_xy[2 * i + 1] = s->xyt[3 * i + 1];
    }
    double least = INFINITY;
    for (int64_t i = 0; i < m; ++i)
        for (int64_t j = i + 1; j < m; ++j) {
            const double* a = s->link_xy + 2 * i;
            const double* b = s->link_xy + 2 * j;
            const double gap = std::fabs(py_hypot(a[0] - b[0], a[1] - b[1]) - s->comm_range);
            if (gap < least) least = gap;
        }
    s->slack_left = std::isnan(least) ? -1.0 : least - 1e-6;
}

}  // extern "C"
