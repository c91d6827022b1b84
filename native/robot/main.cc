// tb-robot: the paper's robot in C++, started by `testbed run` inside the robot's network
// namespace with the Python robot's command line (node/launch.py's NodeArgs). It carries
// nanomsg (the default middleware) and, where built with libzmq, ZeroMQ, with flooded maps;
// for anything else it refuses in one line (exit 2) and the runner starts the Python robot
// instead. `tb-robot --middlewares` prints what this build carries. `--role display` runs the
// display's part that keeps step with the robots (display.cc), with flooded maps; node.nativedisplay
// starts it and draws what it kept once it stopped.
//
// Exit statuses as the Python robot's: 0 the run ended, 1 cannot start (a socket), 2 bad
// arguments or a middleware it does not carry, 3 a part failed.
//
// `tb-robot --decode KIND`, `--encode KIND`, `--timings SCALE MAP_PERIOD` and `--addr K` are
// the contract's self-test (selftest.cc).
// Otherwise the command line is NodeArgs' (args.cc): `--help` prints its listing and
// `--check-args` checks it, each with exit 0 and nothing run.
#include <csignal>
#include <sys/prctl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <cstdio>
#include <cstring>
#include <exception>
#include <memory>
#include <new>
#include <string>
#include <vector>

#include "args.h"
#include "body.h"
#include "display.h"
#include "events.h"
#include "flood.h"
#include "laser.h"
#include "log.h"
#include "messenger.h"
#include "robot.h"

namespace tb {
int selftest_main(const std::vector<std::string>& argv);
}

namespace {

tb::Robot* g_robot = nullptr;
tb::Display* g_display = nullptr;

void on_term(int) {
    // std::atomic<bool>: lock-free, signal-safe
    if (g_robot) g_robot->stopping = true;
    if (g_display) g_display->stopping = true;
}

int fail(const std::string& line, int status) {
    fprintf(stderr, "node: %s\n", line.c_str());
    return status;
}

// The names node/displayreplay.py reads (REPLAY_FILE, STEPPING_FILE) in the display's --out-dir.
const char* const REPLAY_FILE = "replay.bin";
const char* const STEPPING_FILE = "stepping.json";

bool write_file(const std::string& path, const std::string& text) {
    std::string tmp = path + ".part";
    FILE* f = fopen(tmp.c_str(), "we");
    if (!f) return false;
    bool ok = fwrite(text.data(), 1, text.size(), f) == text.size();
    ok = fclose(f) == 0 && ok;
    return ok && rename(tmp.c_str(), path.c_str()) == 0;
}

int display_main(const tb::Args& a, const char* program) {
    std::string me = "r" + std::to_string(a.robot);
    if (a.out_dir.empty()) return fail("the display needs --out-dir", 2);
    if (a.maps != "flood")
        return fail("--maps " + a.maps + ": the C++ display takes flooded maps only; the " +
                        "Python display runs this",
                    2);
    // It is started by node.nativedisplay, which draws what it kept: it must not outlive it.
    prctl(PR_SET_PDEATHSIG, SIGKILL, 0, 0, 0);
    tb::log_init(a.robot);
    std::string title = me + " display";
    prctl(PR_SET_NAME, title.c_str(), 0, 0, 0);
    if (mkdir(a.out_dir.c_str(), 0755) != 0 && errno != EEXIST)
        return fail(me + ": cannot start: " + a.out_dir + ": " + strerror(errno), 1);
    tb::RobotTimings timing;
    timing.time_scale = a.time_scale;
    timing.map_period = a.map_period;
    tb::EventLog events;
    tb::BodyClient link;
    tb::Flooder flooder(a.robot, a.flood_port, a.iface, a.flood, timing.neighbour_hold_s());
    tb::ReplayWriter replay;
    std::string err;
    // An --events file that cannot be opened is bad input (status 2), as in the Python robot.
    if (!events.open(a.events))
        return fail(me + ": cannot open --events '" + a.events + "': " + strerror(errno), 2);
    bool opened = link.open(a.body, a.robot, err, 1) && flooder.open(err) &&
                  replay.open(a.out_dir + "/" + REPLAY_FILE, err);
    if (!opened) return fail(me + ": cannot start: " + err, 1);
    tb::Display display(a, link, flooder, events, replay);
    g_display = &display;
    struct sigaction sa {};
    sa.sa_handler = on_term;
    sigaction(SIGTERM, &sa, nullptr);
    signal(SIGPIPE, SIG_IGN);
    LOG_INFO("node", "display up (C++, %s): maps by %s", program, a.maps.c_str());
    display.run();
    g_display = nullptr;
    bool kept = replay.close();
    if (!kept || !write_file(a.out_dir + "/" + STEPPING_FILE, display.stepping_json()))
        return fail(me + ": cannot keep what the display saw in " + a.out_dir + ": " +
                        strerror(errno),
                    3);
    events.close();
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    std::vector<std::string> args(argv + 1, argv + argc);
    if (!args.empty() && (args[0] == "--decode" || args[0] == "--encode" ||
                          args[0] == "--laser-tables" || args[0] == "--timings" ||
                          args[0] == "--addr"))
        try {
            return tb::selftest_main(args);
        } catch (const std::exception& e) {  // an input asking for more than the machine has
            return fail(args[0] + ": " + e.what(), 2);
        }
    if (args.size() == 1 && args[0] == "--middlewares") {
        printf("%s\n", tb::carried_middlewares().c_str());
        return 0;
    }
    tb::Args a;
    std::string err;
    switch (tb::read_args(args, a, err)) {  // NodeArgs.parse's verdict (args.cc)
    case tb::ArgsVerdict::refused: return fail(err, 2);
    case tb::ArgsVerdict::help: fputs(tb::args_listing(), stdout); return 0;
    case tb::ArgsVerdict::check: return 0;  // --check-args: nothing runs
    case tb::ArgsVerdict::run: break;
    }
    if (a.role == "display") return display_main(a, argv[0]);
    tb::RobotTimings timing;
    timing.time_scale = a.time_scale;
    timing.map_period = a.map_period;
    std::unique_ptr<tb::Messenger> messenger = tb::make_messenger(
        a.middleware, a.robot,
        {a.goal_port, timing.goal_send_timeout_ms(), timing.goal_reconnect_min_ms(),
         timing.goal_reconnect_max_ms()});
    if (!messenger || a.maps != "flood")
        return fail("--middleware " + a.middleware + " --maps " + a.maps +
                        ": this C++ robot carries " + tb::carried_middlewares() +
                        " with flooded maps only; the Python robot runs this",
                    2);
    tb::log_init(a.robot);
    // The process's name as the Python robot's fork server titles it ("r3 robot"): ps, top
    // and the cost benchmark's process kinds read it (exec named it "tb-robot").
    std::string title = "r" + std::to_string(a.robot) + " robot";
    prctl(PR_SET_NAME, title.c_str(), 0, 0, 0);
    tb::EventLog events;
    if (!events.open(a.events))  // bad input (status 2), as in the Python robot
        return fail("r" + std::to_string(a.robot) + ": cannot open --events '" + a.events +
                        "': " + strerror(errno),
                    2);
    tb::BodyClient link;
    tb::Flooder flooder(a.robot, a.flood_port, a.iface, a.flood, timing.neighbour_hold_s());
    std::string bind = a.bind.empty() ? tb::robot_addr(a.robot) : a.bind;
    if (!link.open(a.body, a.robot, err) || !messenger->open(bind, err) || !flooder.open(err))
        return fail("r" + std::to_string(a.robot) + ": cannot start: " + err, 1);
    // The maps and the laser's tables are allocated here: a map or laser too large for the
    // machine is one line and exit 1, as the Python robot's MemoryError would be a crash.
    std::unique_ptr<tb::Robot> made;
    try {
        made = std::make_unique<tb::Robot>(a, timing, link, flooder, *messenger, events);
    } catch (const std::bad_alloc&) {
        return fail("r" + std::to_string(a.robot) + ": cannot start: not enough memory for a " +
                        std::to_string(a.rows) + "x" + std::to_string(a.cols) + " map and a " +
                        std::to_string(a.laser_range) + " m laser",
                    1);
    }
    tb::Robot& robot = *made;
    g_robot = &robot;
    struct sigaction sa {};
    sa.sa_handler = on_term;
    sigaction(SIGTERM, &sa, nullptr);
    signal(SIGPIPE, SIG_IGN);
    LOG_INFO("node", "robot up (C++, %s): team of %d, laser %.1f m, maps by %s", argv[0],
             a.robots, a.laser_range, a.maps.c_str());
    robot.run();
    g_robot = nullptr;
    messenger->close();
    events.close();
    return 0;
}
