// The world's step in compiled code (worldstep.cc): the body link's commands taken into the
// bodies, the deadlines missed counted, the bodies moved. One struct, filled once by
// testbed/world/stepfast.py (a ctypes Structure of the same fields in the same order), holds
// the addresses of the world's arrays; every call takes it. Arrays are C-contiguous; booleans
// are one byte, 0 or 1. Only 8-byte fields, so that the two layouts cannot disagree.
#pragma once

#include <cstdint>

extern "C" {

struct sc_world_step {
    int64_t n;             // robots
    int64_t m;             // body-link sockets: robots 1..n (-1: none), then the displays
    // The bodies (testbed.world.world.World's arrays).
    double* xyt;           // n x 3: x, y, theta
    double* target;        // n x 2: the commanded target where has_target
    uint8_t* has_target;   // n
    uint8_t* alive;        // n: Body.alive
    int64_t* collisions;   // n
    double* path_length;   // n
    const uint8_t* blocked;  // bh x bw: cells a robot's centre may not be in
    int64_t bh, bw;
    double cell, speed;
    // Each move (robot, x, y) in the order World.move appends it to World.paths.
    int64_t* log_i;        // log_cap
    double* log_xy;        // log_cap x 2
    int64_t log_cap, log_len;
    // The robots' records (testbed.run.record.RobotRecord's, while the loop runs).
    const uint8_t* live;   // n: the process is in the run (not crashed, not stopped)
    int64_t* last_cmd;     // n: the latest step whose frame it answered
    int64_t* missed;       // n: deadlines missed
    int64_t* missed_steps; // n x missed_cap: which (the first missed_cap)
    int64_t* missed_len;   // n
    int64_t missed_cap;
    // sc_body_take's arguments (testbed.world.bodylink._Sockets' buffers), for m sockets.
    const int32_t* fds;
    int32_t* taken;
    int64_t* steps;
    uint8_t* go;
    double* xy;
    uint8_t* hung;
    uint8_t* others;
    int64_t others_cap;
    int32_t* counts;
    // Descriptors whose readiness means a robot's process may have exited (fork servers').
    const int32_t* watch_fds;
    int64_t n_watch;
    // What sc_step_take found.
    int64_t others_used;   // sc_body_take's return
    int64_t missed_now;    // robots that missed this step's deadline
    int64_t watch_ready;   // 1: a watched descriptor is readable (or failed)
    // The links' slack (topology.radio.slack, kept by the world): whether a link can have
    // come or gone since the positions the topology controller was last given.
    int64_t links_slack;   // 1: links follow the positions alone (disc model on veth)
    double comm_range;
    double slack_left;     // negative: nothing measured, or spent
    double* link_xy;       // (n + 1) x 2: the positions last given (the display's last)
};

// The world's casts of a step (World.cast_live): sc_world_cast_moved's arguments in one struct
// (node/stepcore.py's WorldCast fills it once: a ctypes call of 37 arguments cost more than
// a step's casts of a lone robot).
struct sc_cast_pack {
    int64_t n;
    const double* xyt;     // n x 3: the poses (the bodies')
    int8_t* has_out;       // n: what each robot's last cast gave (1 ranges, 0 none, -1 not done)
    double* xy;            // n x 2: where each robot was last cast
    uint8_t* want;         // n: scratch
    double map_cell, laser_cell;
    int64_t bias, pad, w;
    const float* dx;
    const float* dy;
    const uint8_t* mark;
    int64_t n_rays, n_samples;
    double step;
    int64_t tabled, frac, buckets;
    const uint8_t* const* sures;
    const float* const* odxs;
    const float* const* odys;
    const int32_t* n_opens;
    const uint8_t* occ;
    uint8_t* seen;
    const uint8_t* free_pad;
    int64_t ph, pw;
    const uint8_t* open_space;
    const int32_t* skip;
    int64_t mh, mw;
    float* ranges_out;
    int8_t* hit_out;
    int64_t fallbacks;     // out: robots the call did nothing for (World.scan's own path)
};

int64_t sc_world_cast_step(sc_cast_pack* p, const uint8_t* live);
double sc_monotonic(void);
double sc_sleep_until(double deadline);
int64_t sc_step_take(sc_world_step* s, int64_t step, int64_t count_missed);
int64_t sc_world_move(sc_world_step* s);
int64_t sc_links_spend(sc_world_step* s);
void sc_links_measure(sc_world_step* s);
double sc_py_hypot(double x, double y);
// 1: subnormal lengths through DBL_MIN, as CPython after 3.11 (see worldstep.cc); 0: not.
void sc_py_hypot_mode(int64_t by_dbl_min);
double sc_py_atan2(double y, double x);

}  // extern "C"
