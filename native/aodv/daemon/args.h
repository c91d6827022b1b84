// The compiled daemon's command line: aodv/__main__.py's, option for option (the table is
// generated from its parser into build/gen/aodv_consts.h by aodv/constgen.py): the same
// flags (unique prefixes too, as argparse takes them; --flag=value), defaults, choices,
// bounds and `--set NAME=VALUE` fields, checked in the same order. A refusal is one line,
// "tb-aodv: error: ...", and exit status 2.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "../params.h"

namespace aodv {

struct Args {
    std::string robot, iface, profile, stats, state, log_level, net;
    // --netns: the namespace (/run/netns/NAME) the daemon enters before it makes any socket;
    // empty: it stays where it was started.
    std::string netns;
    bool has_stats = false, has_state = false;
    double time_scale = 1.0;
    // Between rewrites of the statistics file (--stats-period; 0 given: +inf, only when
    // ready, on SIGUSR1 and at exit).
    double stats_period = 1.0;
    bool no_local_repair = false;
    std::vector<std::string> sets;
    uint32_t net_addr = 0, net_mask = 0;  // the network, host byte order
    int net_prefix = 0;
};

// Parse argv; false with `error` (the line after "error: ") on a usage error, `help` set
// (and nothing else) for -h/--help.
bool parse_args(int argc, char** argv, Args& out, std::string& error, bool& help);
// The usage and option listing -h prints.
std::string usage_text();
// The profile, its overrides and --no-local-repair; false with `error` as
// aodv.__main__.build_params raises it.
bool build_params(const Args& args, Params& out, std::string& error);
// Params.problems(): the section 10 constraints (and plain sanity) broken; empty if none.
std::vector<std::string> problems(const Params& p);
// Python's float(text) and int(text) (whitespace around, underscores between digits).
bool py_float(const std::string& text, double& out);
bool py_int(const std::string& text, long long& out);

}  // namespace aodv
