#include "wire.h"

#include <algorithm>
#include <cmath>
#include <zlib.h>

#include "json.h"
#include "node_args.h"
#include "wirebytes.h"

namespace tb {

namespace {
const char MAGIC[4] = {'R', 'M', 'F', '2'};
using gen::MAP_HDR;
using gen::MAX_CELLS;
using gen::MAX_NEIGHBOURS;

void copy_part(std::string& o, uint16_t sender, std::vector<uint16_t> nb) {
    std::sort(nb.begin(), nb.end());
    if (nb.size() > MAX_NEIGHBOURS) nb.resize(MAX_NEIGHBOURS);
    put16(o, sender);
    put8(o, static_cast<uint8_t>(nb.size()));
    for (uint16_t k : nb) put16(o, k);
}
}  // namespace

std::string pack_flood(const FloodHeader& h, const std::string& payload) {
    std::string o(MAGIC, 4);
    put8(o, h.kind);
    put8(o, h.ttl);
    put16(o, h.origin);
    put32(o, h.seq);
    put32(o, h.step);
    copy_part(o, h.sender, h.neighbours);
    return o + payload;
}

bool unpack_flood(const uint8_t* d, size_t n, FloodHeader& h, std::string& err) {
    if (n < FLOOD_FIXED) {
        err = "flood shorter than its header";
        return false;
    }
    if (memcmp(d, MAGIC, 4) != 0) {
        err = "not a robot flood (bad magic)";
        return false;
    }
    h.kind = d[4];
    h.ttl = d[5];
    h.origin = rd16(d + 6);
    h.seq = rd32(d + 8);
    h.step = rd32(d + 12);
    h.sender = rd16(d + 16);
    // Robots are 1..MAX_FLOOD_ID (node.wire's, generated): checked before anything is kept
    // per origin, so a peer naming 65,535 origins cannot grow the duplicate cache.
    if (h.origin < 1 || h.origin > gen::MAX_FLOOD_ID || h.sender < 1 ||
        h.sender > gen::MAX_FLOOD_ID) {
        err = "flood of origin " + std::to_string(h.origin) + " from " +
              std::to_string(h.sender) + ": robots are 1.." + std::to_string(gen::MAX_FLOOD_ID);
        return false;
    }
    size_t k = d[18];
    size_t end = FLOOD_FIXED + 2 * k;
    if (n < end) {
        err = "flood shorter than its neighbour list";
        return false;
    }
    h.neighbours.resize(k);
    for (size_t i = 0; i < k; ++i) h.neighbours[i] = rd16(d + FLOOD_FIXED + 2 * i);
    h.payload_at = end;
    return true;
}

std::string relayed(const uint8_t* d, size_t n, const FloodHeader& h, uint8_t ttl,
                    uint16_t sender, const std::vector<uint16_t>& neighbours) {
    std::string o((const char*)d, 16);
    o[5] = static_cast<char>(ttl);
    copy_part(o, sender, neighbours);
    o.append((const char*)d + h.payload_at, n - h.payload_at);
    return o;
}

std::string pack_map(double x, double y, const Ternary& t, int r_off, int c_off) {
    int r0 = -1, r1 = -1, c0 = t.w, c1 = -1;
    for (int r = 0; r < t.h; ++r)
        for (int c = 0; c < t.w; ++c)
            if (t.cells[static_cast<size_t>(r) * t.w + c]) {
                if (r0 < 0) r0 = r;
                r1 = r;
                c0 = std::min(c0, c);
                c1 = std::max(c1, c);
            }
    std::string o;
    putf32(o, static_cast<float>(x));
    putf32(o, static_cast<float>(y));
    if (r0 < 0) {  // nothing known: an empty window
        put16(o, 0);
        put16(o, 0);
        put16(o, 0);
        put16(o, 0);
        return o;
    }
    int h = r1 - r0 + 1, w = c1 - c0 + 1;
    put16(o, static_cast<uint16_t>(r0 + r_off));
    put16(o, static_cast<uint16_t>(c0 + c_off));
    put16(o, static_cast<uint16_t>(h));
    put16(o, static_cast<uint16_t>(w));
    size_t cells = static_cast<size_t>(h) * w;
    std::vector<uint8_t> packed((cells + 3) / 4, 0);
    size_t i = 0;
    for (int r = r0; r <= r1; ++r)
        for (int c = c0; c <= c1; ++c, ++i)
            packed[i / 4] |=
                static_cast<uint8_t>(t.cells[static_cast<size_t>(r) * t.w + c] << (2 * (i % 4)));
    uLongf len = compressBound(packed.size());
    std::string blob(len, '\0');
    compress2((Bytef*)&blob[0], &len, packed.data(), packed.size(), 1);
    blob.resize(len);
    return o + blob;
}

bool decode_ternary(int h, int w, const uint8_t* d, size_t n, Ternary& out, std::string& err) {
    if (h < 0 || w < 0 || static_cast<int64_t>(h) * w > MAX_CELLS) {
        err = "bad ternary map size";
        return false;
    }
    out.h = h;
    out.w = w;
    out.cells.assign(static_cast<size_t>(h) * w, 0);
    if (h * w == 0) return true;
    size_t want = (static_cast<size_t>(h) * w + 3) / 4;
    std::vector<uint8_t> raw(want + 1);
    z_stream z{};
    if (inflateInit(&z) != Z_OK) {
        err = "zlib unavailable";
        return false;
    }
    z.next_in = (Bytef*)d;
    z.avail_in = (uInt)n;
    z.next_out = raw.data();
    z.avail_out = (uInt)raw.size();
    int rc = inflate(&z, Z_FINISH);
    size_t got = raw.size() - z.avail_out;
    inflateEnd(&z);
    if (rc == Z_BUF_ERROR && z.avail_out == 0) {
        err = "ternary map payload has the wrong length";
        return false;
    }
    if (rc != Z_STREAM_END) {
        err = "bad ternary map payload";
        return false;
    }
    if (got != want) {
        err = "ternary map payload has the wrong length";
        return false;
    }
    for (size_t i = 0; i < out.cells.size(); ++i) {
        uint8_t v = (raw[i / 4] >> (2 * (i % 4))) & 3;
        if (v > 2) {
            err = "ternary map has an invalid cell value";
            return false;
        }
        out.cells[i] = v;
    }
    return true;
}

bool unpack_map(const uint8_t* d, size_t n, int rows, int cols, MapMsg& out, std::string& err) {
    if (n < MAP_HDR) {
        err = "map payload shorter than its header";
        return false;
    }
    out.x = rdf32(d);
    out.y = rdf32(d + 4);
    out.r0 = rd16(d + 8);
    out.c0 = rd16(d + 10);
    int h = rd16(d + 12), w = rd16(d + 14);
    if (out.r0 + h > rows || out.c0 + w > cols) {
        err = "map does not fit this robot's grid";
        return false;
    }
    if (!std::isfinite(out.x) || !std::isfinite(out.y)) {
        err = "map position is not finite";
        return false;
    }
    return decode_ternary(h, w, d + MAP_HDR, n - MAP_HDR, out.cells, err);
}

bool unpack_beacon(const uint8_t* d, size_t n, double& x, double& y, std::string& err) {
    if (n != 8) {
        err = "beacon payload has the wrong length";
        return false;
    }
    x = rdf32(d);
    y = rdf32(d + 4);
    return true;
}

std::string pack_beacon(double x, double y) {
    std::string o;
    putf32(o, static_cast<float>(x));
    putf32(o, static_cast<float>(y));
    return o;
}

// json.dumps' default separators (", " and ": "), so the bytes are the Python robot's.
const char* msg_kind_name(MsgKind k) { return k == MsgKind::goal ? "goal" : "replan"; }

std::string goal_msg(int sender, int64_t step, double gx, double gy, double cost, bool fallback,
                     int64_t n) {
    std::string o = "{\"k\": \"goal\", \"from\": " + std::to_string(sender) +
                    ", \"step\": " + std::to_string(step) + ", \"goal\": [" + py_float(gx) +
                    ", " + py_float(gy) + "], \"cost\": " + py_float(py_round(cost, 3));
    if (fallback) o += ", \"fallback\": true";
    if (n > 0) o += ", \"n\": " + std::to_string(n);
    return o + "}";
}

std::string replan_msg(int sender, int64_t step, double gx, double gy, int64_t n) {
    std::string o = "{\"k\": \"replan\", \"from\": " + std::to_string(sender) +
                    ", \"step\": " + std::to_string(step) + ", \"goal\": [" + py_float(gx) +
                    ", " + py_float(gy) + "]";
    if (n > 0) o += ", \"n\": " + std::to_string(n);
    return o + "}";
}

namespace {
// Python's isinstance(v, int): JSON integers and booleans.
bool as_int(const Json* v, int64_t& out) {
    if (!v) return false;
    if (v->kind == Json::INT) out = v->i;
    else if (v->kind == Json::BOOL) out = v->b ? 1 : 0;
    else return false;
    return true;
}
}  // namespace

bool parse_msg(const std::string& data, int n_robots, GoalMsg& out, std::string& err) {
    Json m;
    std::string why;
    if (!json_parse(data, m, why)) {
        err = "message is not JSON: " + why;
        return false;
    }
    const Json* k = m.kind == Json::OBJ ? m.get("k") : nullptr;
    if (!k || k->kind != Json::STR || (k->s != "goal" && k->s != "replan")) {
        err = "message has no known kind";
        return false;
    }
    out = GoalMsg();
    out.k = k->s == "goal" ? MsgKind::goal : MsgKind::replan;
    int64_t from, step;
    if (!as_int(m.get("from"), from) || from < 1 || from > n_robots) {
        err = "message sender is not a robot of this team";
        return false;
    }
    out.from = static_cast<int>(from);
    if (!as_int(m.get("step"), step) || step < 0) {
        err = "message step is not a step";
        return false;
    }
    out.step = step;
    const Json* g = m.get("goal");
    if (!g || g->kind != Json::ARR || g->arr.size() != 2 || !g->arr[0].is_number() ||
        !g->arr[1].is_number() || !std::isfinite(g->arr[0].number()) ||
        !std::isfinite(g->arr[1].number())) {
        err = "message goal is not a point";
        return false;
    }
    out.gx = g->arr[0].number();
    out.gy = g->arr[1].number();
    const Json* n = m.get("n");
    if (n && n->kind != Json::NUL) {
        if (n->kind != Json::INT || n->i < 1) {
            err = "message number is not a number >= 1";
            return false;
        }
        out.n = n->i;
    }
    if (out.k == MsgKind::goal) {
        const Json* c = m.get("cost");
        if (!c || !c->is_number() || !std::isfinite(c->number()) || c->number() < 0) {
            err = "goal message has no valid cost";
            return false;
        }
        out.cost = c->number();
        // bool(m.get("fallback", False)): Python's truth of any JSON value.
        const Json* f = m.get("fallback");
        if (f) {
            switch (f->kind) {
                case Json::NUL: out.fallback = false; break;
                case Json::BOOL: out.fallback = f->b; break;
                case Json::INT: out.fallback = f->i != 0; break;
                case Json::REAL: out.fallback = f->d != 0; break;
                case Json::STR: out.fallback = !f->s.empty(); break;
                case Json::ARR: out.fallback = !f->arr.empty(); break;
                case Json::OBJ: out.fallback = !f->obj.empty(); break;
            }
        }
    }
    return true;
}

}  // namespace tb
