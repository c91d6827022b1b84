// The robot's command line: node/launch.py's NodeArgs, the same flags, defaults and bounds,
// so that the runner starts either robot with the same argv. Bad arguments: one line, exit 2.
#pragma once

#include <cstdint>
#include <set>
#include <string>
#include <vector>

namespace tb {

struct Args {
    int robot = 0, robots = 0;
    std::string body, role = "robot", events;
    int rows = 400, cols = 400;
    double cell = 0.05, laser_range = 2.0;
    int laser_rays = 360;
    double speed = 0.1, radius = 0.15;
    int plan_period = 20, map_period = 10;
    double time_scale = 1.0;
    int timer_phase = 0;
    std::string iface = "wlan0";
    int flood_port = 5100;
    std::string flood = "pruned", coordination = "ours";
    int goal_port = 5101;
    std::string middleware = "nanomsg", maps = "flood", bind, out_dir;
    std::set<int64_t> snapshots;  // node.launch.steps: "100,500"
    int video_every = 10;
};

// Parses argv (without the program name); false with the one-line reason in `err`.
bool parse_args(const std::vector<std::string>& argv, Args& out, std::string& err);

}  // namespace tb
