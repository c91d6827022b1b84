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
//   Python's min() and int() where the Python uses them. A target that is not finite is left
//   to World.move itself (nothing is done: it returns 1).
//
// testbed/world/stepfast.py fills the struct (worldstep.h) with the world's arrays and calls
// these; tests/unit/test_step_fast.py holds each equal to its Python twin.

#include "worldstep.h"

#include <poll.h>
#include <time.h>

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

// CPython's vector_norm for two coordinates, given their absolute values and the larger.
double vector_norm2(double a, double b, double max) {
    if (std::isinf(max)) return max;
    if (std::isnan(a) || std::isnan(b)) return NAN;
    if (max == 0.0) return max;
    int max_e;
    std::frexp(max, &max_e);
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

inline double seconds(const struct timespec& t) {
    // time.monotonic(): the nanoseconds as one integer, then a float divided by 1e9.
    const int64_t ns = (int64_t)t.tv_sec * 1000000000 + (int64_t)t.tv_nsec;
    return (double)ns / 1e9;
}

}  // namespace

extern "C" {

double sc_py_hypot(double x, double y) { return py_hypot(x, y); }

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
// with a target has a coordinate that is not finite (World.move's own path then).
int64_t sc_world_move(sc_world_step* s) {
    for (int64_t i = 0; i < s->n; ++i) {
        if (!s->alive[i] || !s->has_target[i]) continue;
        const double* t = s->target + 2 * i;
        const double* p = s->xyt + 3 * i;
        if (!(std::isfinite(t[0]) && std::isfinite(t[1]) && std::isfinite(p[0]) &&
              std::isfinite(p[1])))
            return 1;
    }
    if (s->log_len + s->n > s->log_cap) return 1;  // no room to log the moves: Python's path
    for (int64_t i = 0; i < s->n; ++i) {
        if (!s->alive[i] || !s->has_target[i]) continue;
        double* p = s->xyt + 3 * i;
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

}  // extern "C"
