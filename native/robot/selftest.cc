// The contract's self-test modes (docs/robot-contract.md), for tests that hold the two
// robots to one wire format:
//
//   tb-robot --decode KIND [--robots N] [--map-size RxC]   bytes on stdin -> one JSON line
//   tb-robot --encode KIND                                 one JSON object on stdin -> bytes
//   tb-robot --laser-tables RANGE RAYS CELL                the laser's tables, raw, on stdout
//   tb-robot --timings SCALE MAP_PERIOD                    RobotTimings' durations, one JSON line
//
// KIND: body, flood, map (a flood's map payload), msg (a goal or re-plan message). A decoder
// prints the decoded form, or "refused: <why>" and exits 1; never a crash.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <iterator>
#include <string>
#include <vector>

#include "body.h"
#include "flood.h"
#include "json.h"
#include "laser.h"
#include "robot.h"
#include "wire.h"

namespace tb {

namespace {

std::string read_stdin() {
    std::string s((std::istreambuf_iterator<char>(std::cin)), std::istreambuf_iterator<char>());
    return s;
}

std::string real_list(const std::vector<double>& v) {
    std::string o = "[";
    for (size_t i = 0; i < v.size(); ++i) o += (i ? "," : "") + py_float(v[i]);
    return o + "]";
}

int refused(const std::string& why) {
    printf("refused: %s\n", why.c_str());
    return 1;
}

int decode(const std::string& kind, int robots, int rows, int cols) {
    std::string in = read_stdin();
    const uint8_t* d = reinterpret_cast<const uint8_t*>(in.data());
    std::string err;
    JsonObj o;
    if (kind == "body") {
        BodyMsg m;
        if (!body_parse(d, in.size(), m, err)) return refused(err);
        o.str("kind", body_kind_name(m.kind));
        if (m.kind == BodyKind::hello) o.num("robot", m.robot).num("role", m.role);
        if (m.kind == BodyKind::frame) {
            const Frame& f = m.frame;
            std::vector<double> r(f.ranges.begin(), f.ranges.end());
            o.num("step", f.step).real("x", f.x).real("y", f.y).real("theta", f.theta);
            o.real("sent", f.sent).raw("ranges", real_list(r));
        }
        if (m.kind == BodyKind::cmd)
            o.num("step", m.step).raw("target", m.go ? real_list({m.tx, m.ty}) : "null");
        if (m.kind == BodyKind::done) o.num("step", m.step);
    } else if (kind == "flood") {
        FloodHeader h;
        if (!unpack_flood(d, in.size(), h, err)) return refused(err);
        std::string nb = "[";
        for (size_t i = 0; i < h.neighbours.size(); ++i)
            nb += (i ? "," : "") + std::to_string(h.neighbours[i]);
        o.num("kind", h.kind).num("ttl", h.ttl).num("origin", h.origin).num("seq", h.seq);
        o.num("step", h.step).num("sender", h.sender).raw("neighbours", nb + "]");
        o.num("payload", static_cast<int64_t>(in.size() - h.payload_at));
    } else if (kind == "map") {
        MapMsg m;
        if (!unpack_map(d, in.size(), rows, cols, m, err)) return refused(err);
        std::string cells;
        for (uint8_t c : m.cells.cells) cells += static_cast<char>('0' + c);
        o.real("x", m.x).real("y", m.y).num("r0", m.r0).num("c0", m.c0);
        o.num("h", m.cells.h).num("w", m.cells.w).str("cells", cells);
    } else if (kind == "msg") {
        GoalMsg m;
        if (!parse_msg(in, robots, m, err)) return refused(err);
        o.str("k", msg_kind_name(m.k)).num("from", m.from).num("step", m.step);
        o.raw("goal", real_list({m.gx, m.gy}));
        if (m.k == MsgKind::goal) o.real("cost", m.cost).boolean("fallback", m.fallback);
        o.raw("n", m.n ? std::to_string(m.n) : "null");
    } else {
        fprintf(stderr, "node: --decode %s: one of body, flood, map, msg\n", kind.c_str());
        return 2;
    }
    printf("%s\n", o.text().c_str());
    return 0;
}

// A field as a number; a value no field could hold (not finite, beyond 2^53) is 0.
double num(const Json& o, const char* k, double dflt = 0) {
    const Json* v = o.get(k);
    double d = v && v->is_number() ? v->number() : dflt;
    return std::isfinite(d) && std::fabs(d) < 9e15 ? d : 0;
}

// num() converted to the type of the field it fills.
template <typename T>
T field(const Json& o, const char* k, double dflt = 0) {
    return static_cast<T>(num(o, k, dflt));
}

int encode(const std::string& kind) {
    Json o;
    std::string err, out;
    if (!json_parse(read_stdin(), o, err) || o.kind != Json::OBJ) {
        fprintf(stderr, "node: --encode %s: not a JSON object: %s\n", kind.c_str(), err.c_str());
        return 2;
    }
    const Json* k = o.get("kind");
    std::string what = k && k->kind == Json::STR ? k->s : "";
    if (kind == "body") {
        if (what == "hello") out = body_hello(field<int>(o, "robot"), field<int>(o, "role"));
        else if (what == "cmd") {
            const Json* t = o.get("target");
            bool go = t && t->kind == Json::ARR && t->arr.size() == 2;
            out = body_cmd(field<uint32_t>(o, "step"), go, go ? t->arr[0].number() : 0,
                           go ? t->arr[1].number() : 0);
        } else if (what == "done") out = body_done(field<uint32_t>(o, "step"));
        else if (what == "end") out = "E";
        else if (what == "frame") {
            Frame f;
            f.step = field<uint32_t>(o, "step");
            f.x = num(o, "x");
            f.y = num(o, "y");
            f.theta = num(o, "theta");
            f.sent = num(o, "sent");
            if (const Json* r = o.get("ranges"))
                for (const Json& v : r->arr)
                    f.ranges.push_back(v.is_number() ? static_cast<float>(v.number()) : INFINITY);
            out = body_frame(f);
        }
    } else if (kind == "map") {
        Ternary t;
        t.h = field<int>(o, "h");
        t.w = field<int>(o, "w");
        if (t.h < 0 || t.w < 0 || t.h > 65535 || t.w > 65535 ||
            static_cast<int64_t>(t.h) * t.w > gen::MAX_CELLS) {
            fprintf(stderr, "node: --encode map: h and w in 0..65535, at most 4,000,000 cells\n");
            return 2;
        }
        const Json* c = o.get("cells");
        for (char ch : c ? c->s : "") t.cells.push_back(static_cast<uint8_t>(ch - '0'));
        t.cells.resize(static_cast<size_t>(t.h) * t.w, 0);
        out = pack_map(num(o, "x"), num(o, "y"), t, field<int>(o, "r0"), field<int>(o, "c0"));
    } else if (kind == "flood") {
        FloodHeader h;
        h.kind = field<uint8_t>(o, "kind_code", KIND_MAP);
        h.ttl = field<uint8_t>(o, "ttl");
        h.origin = field<uint16_t>(o, "origin");
        h.seq = field<uint32_t>(o, "seq");
        h.step = field<uint32_t>(o, "step");
        h.sender = field<uint16_t>(o, "sender");
        if (const Json* nb = o.get("neighbours"))
            for (const Json& v : nb->arr)
                h.neighbours.push_back(static_cast<uint16_t>(v.number()));
        const Json* p = o.get("payload");
        out = pack_flood(h, p && p->kind == Json::STR ? p->s : "");
    } else if (kind == "msg") {
        const Json* g = o.get("goal");
        double gx = g && g->arr.size() == 2 ? g->arr[0].number() : 0;
        double gy = g && g->arr.size() == 2 ? g->arr[1].number() : 0;
        const Json* f = o.get("fallback");
        if (what == "goal")
            out = goal_msg(field<int>(o, "from"), field<int64_t>(o, "step"), gx, gy, num(o, "cost"),
                           f && f->kind == Json::BOOL && f->b, field<int64_t>(o, "n"));
        else
            out = replan_msg(field<int>(o, "from"), field<int64_t>(o, "step"), gx, gy,
                             field<int64_t>(o, "n"));
    }
    if (out.empty()) {
        fprintf(stderr, "node: --encode %s: nothing to encode for kind %s\n", kind.c_str(),
                what.c_str());
        return 2;
    }
    fwrite(out.data(), 1, out.size(), stdout);
    return 0;
}

int laser_tables(double range, int rays, double cell) {
    Laser L(range, rays, cell);
    L.prepare_tables();
    auto put = [](const void* p, size_t n) { fwrite(p, 1, n, stdout); };
    put(L.dx.data(), 4 * L.dx.size());
    put(L.dy.data(), 4 * L.dy.size());
    put(L.mark.data(), L.mark.size());
    for (const MarkTable& t : L.tables) {
        int32_t n = static_cast<int32_t>(t.odx.size());
        put(t.sure.data(), t.sure.size());
        put(&n, 4);
        put(t.odx.data(), 4 * t.odx.size());
        put(t.ody.data(), 4 * t.ody.size());
    }
    return 0;
}

// RobotTimings' durations at this time scale and map period, named as node.timing's
// properties (tests/unit/test_robot_consts.py holds them equal to the Python robot's).
int timings(const std::vector<std::string>& argv) {
    char *e1 = nullptr, *e2 = nullptr;
    double scale = argv.size() == 3 ? strtod(argv[1].c_str(), &e1) : NAN;
    long period = argv.size() == 3 ? strtol(argv[2].c_str(), &e2, 10) : 0;
    if (argv.size() != 3 || *e1 || *e2 || !(scale >= gen::TIME_SCALE_MIN) ||
        !(scale <= gen::TIME_SCALE_MAX) || period < 1 || period > gen::WHOLE_MAX) {
        fprintf(stderr, "node: --timings SCALE MAP_PERIOD: SCALE in [%g, %g], MAP_PERIOD >= 1\n",
                gen::TIME_SCALE_MIN, gen::TIME_SCALE_MAX);
        return 2;
    }
    RobotTimings t;
    t.time_scale = scale;
    t.map_period = static_cast<int>(period);
    JsonObj o;
    o.real("step_order_wait_s", t.step_order_wait_s());
    o.real("neighbour_hold_s", t.neighbour_hold_s());
    o.num("goal_send_timeout_ms", t.goal_send_timeout_ms());
    o.num("goal_reconnect_min_ms", t.goal_reconnect_min_ms());
    o.num("goal_reconnect_max_ms", t.goal_reconnect_max_ms());
    o.real("flood_linger_s", t.flood_linger_s());
    printf("%s\n", o.text().c_str());
    return 0;
}

}  // namespace

int selftest_main(const std::vector<std::string>& argv) {
    if (argv[0] == "--timings") return timings(argv);
    if (argv[0] == "--addr") {  // robot K's address (tests/unit/test_robot_consts.py)
        char* e = nullptr;
        long k = argv.size() == 2 ? strtol(argv[1].c_str(), &e, 10) : 0;
        if (argv.size() != 2 || *e || k < 1 || k > gen::WHOLE_MAX) {
            fprintf(stderr, "node: --addr K: K >= 1\n");
            return 2;
        }
        printf("%s\n", robot_addr(static_cast<int>(k)).c_str());
        return 0;
    }
    if (argv[0] == "--laser-tables") {
        if (argv.size() != 4) {
            fprintf(stderr, "node: --laser-tables RANGE RAYS CELL\n");
            return 2;
        }
        char *e1 = nullptr, *e2 = nullptr, *e3 = nullptr;
        double range = strtod(argv[1].c_str(), &e1), cell = strtod(argv[3].c_str(), &e3);
        long rays = strtol(argv[2].c_str(), &e2, 10);
        if (*e1 || *e2 || *e3 || !(range > 0 && range <= MAX_RANGE_M) || !(cell > 0.001) ||
            rays < 1 || rays > 100000 || range / cell > 10000) {
            fprintf(stderr, "node: --laser-tables: RANGE in (0, 30] m, RAYS >= 1, CELL > 1 mm\n");
            return 2;
        }
        return laser_tables(range, static_cast<int>(rays), cell);
    }
    if (argv.size() < 2) {
        fprintf(stderr, "node: %s KIND\n", argv[0].c_str());
        return 2;
    }
    // body.cc's and flood.cc's own self-tests: a frame as a robot's body link takes it, and
    // the flood filter's verdicts on a sequence of (origin, seq).
    if (argv[0] == "--decode" && argv[1] == "frame") return body_frame_selftest(argv, read_stdin());
    if (argv[0] == "--decode" && argv[1] == "floodseq") return flood_seq_selftest(read_stdin());
    int robots = 10, rows = 400, cols = 400;
    for (size_t i = 2; i + 1 < argv.size(); i += 2) {
        if (argv[i] == "--robots") robots = atoi(argv[i + 1].c_str());
        if (argv[i] == "--map-size") sscanf(argv[i + 1].c_str(), "%dx%d", &rows, &cols);
    }
    return argv[0] == "--decode" ? decode(argv[1], robots, rows, cols) : encode(argv[1]);
}

}  // namespace tb
