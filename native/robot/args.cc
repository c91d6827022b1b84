// The robot's command line, read as node/launch.py's NodeArgs.parse reads it, from the table
// make writes from NodeArgs (build/gen/node_args.h, node/argsgen.py): the flags, their types,
// bounds, choices, defaults and help are there, not here. Here: how each type is spelled
// (node.launch's WHOLE and REAL, robot_number, shape, steps) and NodeArgs.refusal's checks
// across flags. tests/unit/test_robot_cli_contract.py holds the two robots to one verdict.
#include "args.h"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "laser.h"
#include "node_args.h"

namespace tb {

namespace {

using gen::Flag;
using gen::Kind;

static_assert(gen::MAX_RANGE_M == MAX_RANGE_M, "laser.h's MAX_RANGE_M is node.rays'");

// Where each NodeArgs field goes, in NodeArgs' order. The static_asserts below hold this
// list to the generated table, name for name and type for type: a field added to NodeArgs
// and not here stops the build.
struct Binding {
    const char* field;
    int Args::*whole;
    double Args::*real;
    std::string Args::*text;
    std::set<int64_t> Args::*steps;
};

constexpr Binding W(const char* f, int Args::*m) { return {f, m, nullptr, nullptr, nullptr}; }
constexpr Binding R(const char* f, double Args::*m) { return {f, nullptr, m, nullptr, nullptr}; }
constexpr Binding T(const char* f, std::string Args::*m) {
    return {f, nullptr, nullptr, m, nullptr};
}
constexpr Binding S(const char* f, std::set<int64_t> Args::*m) {
    return {f, nullptr, nullptr, nullptr, m};
}
constexpr Binding SHAPE(const char* f) { return {f, nullptr, nullptr, nullptr, nullptr}; }

constexpr Binding BINDINGS[] = {
    W("robot", &Args::robot),
    W("robots", &Args::robots),
    T("body", &Args::body),
    T("role", &Args::role),
    T("events", &Args::events),
    SHAPE("map_size"),  // rows and cols
    R("cell", &Args::cell),
    R("laser_range", &Args::laser_range),
    W("laser_rays", &Args::laser_rays),
    R("speed", &Args::speed),
    R("radius", &Args::radius),
    W("plan_period", &Args::plan_period),
    W("map_period", &Args::map_period),
    R("time_scale", &Args::time_scale),
    W("timer_phase", &Args::timer_phase),
    T("iface", &Args::iface),
    W("flood_port", &Args::flood_port),
    T("flood", &Args::flood),
    T("coordination", &Args::coordination),
    W("goal_port", &Args::goal_port),
    T("middleware", &Args::middleware),
    T("maps", &Args::maps),
    T("bind", &Args::bind),
    T("out_dir", &Args::out_dir),
    S("snapshots", &Args::snapshots),
    W("video_every", &Args::video_every),
};
constexpr int N_BINDINGS = sizeof(BINDINGS) / sizeof(BINDINGS[0]);

constexpr bool same_text(const char* a, const char* b) {
    while (*a && *a == *b) ++a, ++b;
    return *a == *b;
}

constexpr bool fits(const Flag& f, const Binding& b) {
    switch (f.kind) {
    case Kind::Int:
    case Kind::Robot: return b.whole != nullptr;
    case Kind::Real: return b.real != nullptr;
    case Kind::String:
    case Kind::Choice: return b.text != nullptr;
    case Kind::Steps: return b.steps != nullptr;
    case Kind::Shape: return same_text(b.field, "map_size");
    }
    return false;
}

constexpr bool bindings_match() {
    for (int i = 0; i < gen::N_FLAGS; ++i)
        if (!same_text(gen::FLAGS[i].field, BINDINGS[i].field) || !fits(gen::FLAGS[i], BINDINGS[i]))
            return false;
    return true;
}

static_assert(N_BINDINGS == gen::N_FLAGS, "NodeArgs has a field args.cc does not bind");
static_assert(bindings_match(), "args.cc's BINDINGS are not NodeArgs' fields in order");

// As Python's repr of a str quotes it, near enough to keep the reason on one line.
std::string quoted(const std::string& t) {
    std::string out = "'";
    for (unsigned char c : t) {
        char buf[8];
        if (c == '\\' || c == '\'') {
            out += '\\';
            out += static_cast<char>(c);
        } else if (c == '\n') {
            out += "\\n";
        } else if (c == '\t') {
            out += "\\t";
        } else if (c == '\r') {
            out += "\\r";
        } else if (c < 0x20 || c == 0x7f) {
            snprintf(buf, sizeof buf, "\\x%02x", c);
            out += buf;
        } else {
            out += static_cast<char>(c);
        }
    }
    return out + "'";
}

std::string number_text(double v) {
    char buf[64];
    snprintf(buf, sizeof buf, "%g", v);
    return buf;
}

bool ascii_digit(char c) { return c >= '0' && c <= '9'; }

bool all_digits(const std::string& t, size_t lo, size_t hi) {
    if (t.size() < lo || t.size() > hi) return false;
    for (char c : t)
        if (!ascii_digit(c)) return false;
    return true;
}

// Digits (node.launch: [0-9]+) as a value; false beyond WHOLE_MAX, however many zeros lead.
bool digits_value(const std::string& d, long long& v) {
    size_t i = d.find_first_not_of('0');
    std::string sig = i == std::string::npos ? "" : d.substr(i);
    if (sig.size() > 10) return false;
    v = sig.empty() ? 0 : std::stoll(sig);
    return v <= gen::WHOLE_MAX;
}

// node.launch.WHOLE: -?[0-9]+
bool whole_spelling(const std::string& t) {
    size_t i = !t.empty() && t[0] == '-' ? 1 : 0;
    return all_digits(t.substr(i), 1, std::string::npos);
}

// node.launch.REAL: -?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][-+]?[0-9]+)?
bool real_spelling(const std::string& t) {
    size_t i = 0, n = t.size();
    auto digits = [&]() {
        size_t from = i;
        while (i < n && ascii_digit(t[i])) ++i;
        return i - from;
    };
    if (i < n && t[i] == '-') ++i;
    size_t before = digits();
    if (i < n && t[i] == '.') {
        ++i;
        size_t after = digits();
        if (!before && !after) return false;
    } else if (!before) {
        return false;
    }
    if (i < n && (t[i] == 'e' || t[i] == 'E')) {
        ++i;
        if (i < n && (t[i] == '-' || t[i] == '+')) ++i;
        if (!digits()) return false;
    }
    return i == n;
}

// common.argtypes.number's bounds, in its order.
bool within(const Flag& f, double v, const std::string& t, std::string& err) {
    std::string why;
    if (f.has_above && !(v > f.above))
        why = "greater than " + number_text(f.above);
    else if (f.has_minimum && v < f.minimum)
        why = f.minimum == 0 ? "not negative" : "at least " + number_text(f.minimum);
    else if (f.has_maximum && std::fabs(v) > f.maximum)
        why = "within " + number_text(f.maximum) + " of 0";
    if (why.empty()) return true;
    err = "argument " + std::string(f.flag) + ": " + f.flag + " must be " + why + ", not " + t;
    return false;
}

// One flag's value into `a`, as NodeArgs' parser reads it; false with the line in `err`.
bool set(int at, const std::string& t, Args& a, std::string& err) {
    const Flag& f = gen::FLAGS[at];
    const Binding& b = BINDINGS[at];
    std::string arg = "argument " + std::string(f.flag) + ": ";
    switch (f.kind) {
    case Kind::Int: {
        long long v = 0;
        if (!whole_spelling(t)) {
            err = arg + f.flag + " must be a whole number, not " + quoted(t);
            return false;
        }
        if (!digits_value(t[0] == '-' ? t.substr(1) : t, v)) {
            err = arg + f.flag + " must be within " + std::to_string(gen::WHOLE_MAX) +
                  " of 0, not " + t;
            return false;
        }
        if (t[0] == '-') v = -v;
        if (!within(f, static_cast<double>(v), t, err)) return false;
        a.*b.whole = static_cast<int>(v);
        return true;
    }
    case Kind::Real: {
        if (!real_spelling(t)) {
            err = arg + f.flag + " must be a number, not " + quoted(t);
            return false;
        }
        double v = strtod(t.c_str(), nullptr);
        if (!std::isfinite(v)) {
            err = arg + f.flag + " must be finite, not " + quoted(t);
            return false;
        }
        if (!within(f, v, t, err)) return false;
        a.*b.real = v;
        return true;
    }
    case Kind::String:
        a.*b.text = t;
        return true;
    case Kind::Choice:
        for (int i = 0; i < f.n_choices; ++i)
            if (t == f.choices[i]) {
                a.*b.text = t;
                return true;
            }
        err = arg + "invalid choice: " + quoted(t);
        return false;
    case Kind::Robot: {  // node.launch.robot_number: r?[0-9]{1,ROBOT_DIGITS}, at least 1
        std::string d = !t.empty() && t[0] == 'r' ? t.substr(1) : t;
        if (!all_digits(d, 1, gen::ROBOT_DIGITS) || std::stoi(d) < 1) {
            err = arg + quoted(t) + " is not a robot name like r3";
            return false;
        }
        a.*b.whole = std::stoi(d);
        return true;
    }
    case Kind::Shape: {  // node.launch.shape: [0-9]{1,SHAPE_DIGITS}x[0-9]{1,SHAPE_DIGITS}
        size_t x = t.find('x');
        std::string r = t.substr(0, x), c = x == std::string::npos ? "" : t.substr(x + 1);
        if (!all_digits(r, 1, gen::SHAPE_DIGITS) || !all_digits(c, 1, gen::SHAPE_DIGITS) ||
            std::stoi(r) < 1 || std::stoi(c) < 1) {
            err = arg + quoted(t) + " is not ROWSxCOLS";
            return false;
        }
        a.rows = std::stoi(r);
        a.cols = std::stoi(c);
        return true;
    }
    case Kind::Steps: {  // node.launch.steps: [0-9]+ within WHOLE_MAX, comma-separated
        std::set<int64_t> out;
        for (size_t at = 0; at <= t.size();) {
            size_t end = std::min(t.find(',', at), t.size());
            std::string part = t.substr(at, end - at);
            at = end + 1;
            if (part.empty()) continue;
            long long v = 0;
            if (!all_digits(part, 1, std::string::npos) || !digits_value(part, v)) {
                err = arg + quoted(t) + " is not a list of steps";
                return false;
            }
            out.insert(v);
        }
        a.*b.steps = std::move(out);
        return true;
    }
    }
    return false;
}

int flag_index(const std::string& name) {
    for (int i = 0; i < gen::N_FLAGS; ++i)
        if (name == gen::FLAGS[i].flag) return i;
    return -1;
}

// NodeArgs.refusal: what is wrong across flags, or "".
std::string refusal(const Args& a) {
    if (!(a.cell <= a.laser_range && a.laser_range <= gen::MAX_RANGE_M))
        return "--laser-range " + number_text(a.laser_range) + " must be at least a cell (" +
               number_text(a.cell) + " m) and at most " + number_text(gen::MAX_RANGE_M) + " m";
    if (a.laser_range / a.cell > gen::MAX_LASER_CELLS)
        return "--laser-range " + number_text(a.laser_range) + " is more than " +
               number_text(gen::MAX_LASER_CELLS) + " cells of " + number_text(a.cell) + " m";
    if (a.role == "display" && a.out_dir.empty()) return "the display needs --out-dir";
    if (a.maps == "pubsub") {
        std::string names;
        for (int i = 0; i < gen::N_PUBSUB_MIDDLEWARES; ++i) {
            if (a.middleware == gen::PUBSUB_MIDDLEWARES[i]) return "";
            names += std::string(i ? " or " : "") + gen::PUBSUB_MIDDLEWARES[i];
        }
        return "--maps pubsub needs --middleware " + names + " (not " + a.middleware +
               "): maps are published on their topics";
    }
    return "";
}

}  // namespace

const char* args_listing() { return gen::LISTING; }

ArgsVerdict read_args(const std::vector<std::string>& argv, Args& out, std::string& err) {
    out = Args();
    for (int i = 0; i < gen::N_FLAGS; ++i)
        if (gen::FLAGS[i].default_text && !set(i, gen::FLAGS[i].default_text, out, err)) {
            err = "NodeArgs' default does not read back: " + err;
            return ArgsVerdict::refused;
        }
    // node.launch._tokens: a flag's value is the next argument, whatever it is, or follows '='.
    std::vector<std::pair<int, std::string>> given;
    std::string unknown;
    bool check = false;
    for (size_t i = 0; i < argv.size();) {
        const std::string& token = argv[i++];
        for (const char* h : gen::HELP_FLAGS)
            if (token == h) return ArgsVerdict::help;
        if (token == gen::CHECK_FLAG) {
            check = true;
            continue;
        }
        bool dashes = token.rfind("--", 0) == 0;
        size_t eq = dashes ? token.find('=') : std::string::npos;
        int at = flag_index(token.substr(0, eq));
        if (at < 0) {
            unknown += (unknown.empty() ? "" : " ") + quoted(token);
        } else if (eq != std::string::npos) {
            given.emplace_back(at, token.substr(eq + 1));
        } else if (i < argv.size()) {
            given.emplace_back(at, argv[i++]);
        } else {
            err = "argument " + token + ": expected one argument";
            return ArgsVerdict::refused;
        }
    }
    if (!unknown.empty()) {
        err = "unrecognized arguments: " + unknown;
        return ArgsVerdict::refused;
    }
    std::vector<bool> seen(gen::N_FLAGS);
    for (const auto& [at, value] : given) {
        if (!set(at, value, out, err)) return ArgsVerdict::refused;
        seen[at] = true;
    }
    std::string missing;
    for (int i = 0; i < gen::N_FLAGS; ++i)
        if (gen::FLAGS[i].required && !seen[i])
            missing += (missing.empty() ? "" : ", ") + std::string(gen::FLAGS[i].flag);
    if (!missing.empty()) {
        err = "the following arguments are required: " + missing;
        return ArgsVerdict::refused;
    }
    err = refusal(out);
    if (!err.empty()) return ArgsVerdict::refused;
    return check ? ArgsVerdict::check : ArgsVerdict::run;
}

}  // namespace tb
