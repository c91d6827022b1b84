// The robot's command line: node/launch.py's NodeArgs, the same flags, defaults and bounds,
// so that the runner starts either robot with the same argv. They are not typed here: make
// writes them from NodeArgs into build/gen/node_args.h (node/argsgen.py), and args.cc reads
// argv by that table. Bad arguments: one line, exit 2 (docs/robot-contract.md section 5).
#pragma once

#include <cstdint>
#include <set>
#include <string>
#include <vector>

namespace tb {

// One member per NodeArgs field, of the same name (map_size: rows and cols); their values
// before parse_args are placeholders: parse_args sets every default from NodeArgs'.
struct Args {
    int robot = 0, robots = 0;
    std::string body, role, events;
    int rows = 0, cols = 0;
    double cell = 0, laser_range = 0;
    int laser_rays = 0;
    double speed = 0, radius = 0;
    int plan_period = 0, map_period = 0;
    double time_scale = 0;
    int timer_phase = 0;
    std::string iface;
    int flood_port = 0;
    std::string flood, coordination;
    int goal_port = 0;
    std::string middleware, maps, bind, out_dir;
    std::set<int64_t> snapshots;  // node.launch.steps: "100,500"
    int video_every = 0;
};

// What a command line asks: run, print the listing (-h, --help; exit 0), only check it
// (--check-args; exit 0), or nothing, for it is refused (exit 2).
enum class ArgsVerdict { run, help, check, refused };

// Reads argv (without the program name) as NodeArgs.parse does; `refused` with the one-line
// reason in `err`.
ArgsVerdict read_args(const std::vector<std::string>& argv, Args& out, std::string& err);

// What -h and --help print: node.launch.listing("tb-robot").
const char* args_listing();

}  // namespace tb
