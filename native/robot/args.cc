#include "args.h"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <functional>
#include <map>
#include <set>

namespace tb {

namespace {

using Setter = std::function<bool(const std::string&, Args&, std::string&)>;

std::string quoted(const std::string& t) { return "'" + t + "'"; }

bool all_digits(const std::string& t, size_t lo, size_t hi) {
    if (t.size() < lo || t.size() > hi) return false;
    for (char c : t)
        if (c < '0' || c > '9') return false;
    return true;
}

// Python's int(): optional blanks and sign, digits with single underscores between them.
bool int_text(const std::string& t, std::string& digits) {
    size_t a = t.find_first_not_of(" \t"), b = t.find_last_not_of(" \t");
    if (a == std::string::npos) return false;
    std::string s = t.substr(a, b - a + 1);
    size_t i = (s[0] == '-' || s[0] == '+') ? 1 : 0;
    digits = s.substr(0, i);
    bool prev_digit = false;
    for (; i < s.size(); ++i) {
        if (s[i] >= '0' && s[i] <= '9') {
            digits += s[i];
            prev_digit = true;
        } else if (s[i] == '_' && prev_digit && i + 1 < s.size()) {
            prev_digit = false;
        } else {
            return false;
        }
    }
    return prev_digit;
}

// common.argtypes.number: a finite int or float, within the bounds.
Setter number_int(int Args::*field, const char* flag, const char* bound, long lo) {
    return [=](const std::string& t, Args& a, std::string& err) {
        std::string digits;
        if (!int_text(t, digits)) {
            err = std::string(flag) + " must be a whole number, not " + quoted(t);
            return false;
        }
        errno = 0;
        long v = strtol(digits.c_str(), nullptr, 10);
        if (errno || v > 1000000000L || v < -1000000000L) {
            err = std::string(flag) + " is out of range: " + t;
            return false;
        }
        if ((bound[0] == '>' && !(v > lo)) || (bound[0] == 'm' && v < lo)) {
            err = std::string(flag) + " must be " +
                  (bound[0] == '>' ? "greater than " : "at least ") + std::to_string(lo) +
                  ", not " + t;
            return false;
        }
        a.*field = (int)v;
        return true;
    };
}

Setter number_real(double Args::*field, const char* flag) {
    return [=](const std::string& t, Args& a, std::string& err) {
        char* end = nullptr;
        errno = 0;
        double v = strtod(t.c_str(), &end);
        if (t.empty() || *end != '\0' || t.find_first_of("xXpP") != std::string::npos) {
            err = std::string(flag) + " must be a number, not " + quoted(t);
            return false;
        }
        if (!std::isfinite(v)) {
            err = std::string(flag) + " must be finite, not " + quoted(t);
            return false;
        }
        if (!(v > 0)) {
            err = std::string(flag) + " must be greater than 0, not " + t;
            return false;
        }
        a.*field = v;
        return true;
    };
}

Setter text(std::string Args::*field) {
    return [=](const std::string& t, Args& a, std::string&) {
        a.*field = t;
        return true;
    };
}

Setter choice(std::string Args::*field, const char* flag, std::set<std::string> allowed) {
    return [=](const std::string& t, Args& a, std::string& err) {
        if (!allowed.count(t)) {
            err = std::string("argument ") + flag + ": invalid choice: " + quoted(t);
            return false;
        }
        a.*field = t;
        return true;
    };
}

// node.launch.steps: comma-separated whole numbers as Python's int() reads them, blank
// parts skipped.
bool steps_list(const std::string& t, Args& a, std::string& err) {
    std::set<int64_t> out;
    for (size_t at = 0; at <= t.size();) {
        size_t end = std::min(t.find(',', at), t.size());
        std::string part = t.substr(at, end - at), digits;
        at = end + 1;
        if (part.find_first_not_of(" \t") == std::string::npos) continue;
        bool whole = int_text(part, digits);
        errno = 0;
        long long v = whole ? strtoll(digits.c_str(), nullptr, 10) : 0;
        if (!whole || errno) {
            err = "argument --snapshots: " + quoted(t) + " is not a list of steps";
            return false;
        }
        out.insert(v);
    }
    a.snapshots = std::move(out);
    return true;
}

const std::map<std::string, Setter>& table() {
    static const std::map<std::string, Setter> t = {
        {"--robot",
         [](const std::string& v, Args& a, std::string& err) {
             std::string d = !v.empty() && v[0] == 'r' ? v.substr(1) : v;
             if (!all_digits(d, 1, 3) || std::stoi(d) < 1) {
                 err = "argument --robot: " + quoted(v) + " is not a robot name like r3";
                 return false;
             }
             a.robot = std::stoi(d);
             return true;
         }},
        {"--robots", number_int(&Args::robots, "--robots", ">", 0)},
        {"--body", text(&Args::body)},
        {"--role", choice(&Args::role, "--role", {"robot", "display"})},
        {"--events", text(&Args::events)},
        {"--map-size",
         [](const std::string& v, Args& a, std::string& err) {
             size_t x = v.find('x');
             std::string r = v.substr(0, x), c = x == std::string::npos ? "" : v.substr(x + 1);
             if (!all_digits(r, 1, 5) || !all_digits(c, 1, 5) || std::stoi(r) < 1 ||
                 std::stoi(c) < 1) {
                 err = "argument --map-size: " + quoted(v) + " is not ROWSxCOLS";
                 return false;
             }
             a.rows = std::stoi(r);
             a.cols = std::stoi(c);
             return true;
         }},
        {"--cell", number_real(&Args::cell, "--cell")},
        {"--laser-range", number_real(&Args::laser_range, "--laser-range")},
        {"--laser-rays", number_int(&Args::laser_rays, "--laser-rays", "m", 4)},
        {"--speed", number_real(&Args::speed, "--speed")},
        {"--radius", number_real(&Args::radius, "--radius")},
        {"--plan-period", number_int(&Args::plan_period, "--plan-period", ">", 0)},
        {"--map-period", number_int(&Args::map_period, "--map-period", "m", 1)},
        {"--time-scale", number_real(&Args::time_scale, "--time-scale")},
        {"--timer-phase", number_int(&Args::timer_phase, "--timer-phase", "-", 0)},
        {"--iface", text(&Args::iface)},
        {"--flood-port", number_int(&Args::flood_port, "--flood-port", ">", 0)},
        {"--flood", choice(&Args::flood, "--flood", {"pruned", "blind"})},
        {"--coordination", choice(&Args::coordination, "--coordination", {"paper", "ours"})},
        {"--goal-port", number_int(&Args::goal_port, "--goal-port", ">", 0)},
        {"--middleware", choice(&Args::middleware, "--middleware",
                                {"nanomsg", "zeromq", "zeromq-reqrep", "zenoh", "dds"})},
        {"--maps", choice(&Args::maps, "--maps", {"flood", "pubsub"})},
        {"--bind", text(&Args::bind)},
        {"--out-dir", text(&Args::out_dir)},
        {"--snapshots", steps_list},
        {"--video-every", number_int(&Args::video_every, "--video-every", ">", 0)},
    };
    return t;
}

}  // namespace

bool parse_args(const std::vector<std::string>& argv, Args& out, std::string& err) {
    out = Args();
    std::set<std::string> given;
    for (size_t i = 0; i < argv.size(); ++i) {
        std::string flag = argv[i], value;
        size_t eq = flag.find('=');
        bool inline_value = flag.rfind("--", 0) == 0 && eq != std::string::npos;
        if (inline_value) {
            value = flag.substr(eq + 1);
            flag = flag.substr(0, eq);
        }
        auto it = table().find(flag);
        if (it == table().end()) {
            err = "unrecognized arguments: " + argv[i];
            return false;
        }
        if (!inline_value) {
            if (i + 1 >= argv.size()) {
                err = "argument " + flag + ": expected one argument";
                return false;
            }
            value = argv[++i];
        }
        if (!it->second(value, out, err)) return false;
        given.insert(flag);
    }
    for (const char* req : {"--robot", "--robots", "--body"})
        if (!given.count(req)) {
            err = std::string("the following arguments are required: ") + req;
            return false;
        }
    return true;
}

}  // namespace tb
