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
};

double sc_monotonic(void);
double sc_sleep_until(double deadline);
int64_t sc_step_take(sc_world_step* s, int64_t step, int64_t count_missed);
int64_t sc_world_move(sc_world_step* s);
double sc_py_hypot(double x, double y);
double sc_py_atan2(double y, double x);

}  // extern "C"
