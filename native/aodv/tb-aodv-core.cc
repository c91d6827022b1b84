// tb-aodv-core: drives the compiled AODV core from a file of events, one JSON object a line
// on stdin, and prints what it did on stdout in the canonical form that aodv/coretrace.py
// prints for the Python core, so that any event file can be replayed against both and the
// outputs compared line for line (docs/aodv.md, "Two cores").
//
// Events ("now" in seconds; addresses dotted quads; bytes as hex):
//   {"ev":"init","now":0,"addr":"10.0.0.1","params":{"profile":"rfc",...},
//    "rebooted":false,"seq":0,"rreq_id":0}                 a new core (the old one goes)
//   {"ev":"control","now":1.5,"src":"10.0.0.2","ttl":1,"bytes":"<hex of the datagram>"}
//   {"ev":"no_route","now":..,"src":..,"dst":..,"packet":"<hex>"}
//   {"ev":"route_used","now":..,"addr":..}   {"ev":"routes_used","now":..,"addrs":[..]}
//   {"ev":"link_lost","now":..,"neighbor":..}
//   {"ev":"timer","now":..}   (without "now": at the core's next deadline, or the last now
//                              if that is later)
//   {"ev":"dump"}             the core's state (routes, neighbours, discoveries, kernel copy)
// Output per event: a control event first prints {"decoded":[..]} or {"malformed":true};
// then one line per action, in order; then {"now":..,"next":..,"dropped":{..}} ending the
// event. A line that is not a valid event prints {"error":".."} instead. Every float is
// printed with "%.17g", which names each double exactly.
#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "core.h"

using namespace aodv;

namespace {

// == a small JSON reader (objects, arrays, strings, numbers, true/false/null) ==============
struct J {
    enum T { Null, Bool, Num, Str, Arr, Obj } t = Null;
    bool b = false;
    double num = 0;
    bool integral = false;
    long long i = 0;
    std::string s;
    std::vector<J> a;
    std::vector<std::pair<std::string, J>> o;

    const J* get(const char* k) const {
        if (t != Obj) return nullptr;
        for (const auto& kv : o)
            if (kv.first == k) return &kv.second;
        return nullptr;
    }
};

struct Bad : std::runtime_error {
    using std::runtime_error::runtime_error;
};

class Reader {
  public:
    explicit Reader(const std::string& s) : s_(s) {}
    J parse() {
        J v = value(0);
        ws();
        if (i_ != s_.size()) throw Bad("trailing characters");
        return v;
    }

  private:
    void ws() {
        while (i_ < s_.size() && (s_[i_] == ' ' || s_[i_] == '\t' || s_[i_] == '\r' || s_[i_] == '\n'))
            ++i_;
    }
    bool lit(const char* w) {
        size_t n = std::strlen(w);
        if (s_.compare(i_, n, w) == 0) {
            i_ += n;
            return true;
        }
        return false;
    }
    J value(int depth) {
        if (depth > 32) throw Bad("nested too deep");
        ws();
        if (i_ >= s_.size()) throw Bad("unexpected end");
        J v;
        char c = s_[i_];
        if (c == '{') {
            v.t = J::Obj;
            ++i_;
            ws();
            if (i_ < s_.size() && s_[i_] == '}') {
                ++i_;
                return v;
            }
            for (;;) {
                ws();
                J k = value(depth + 1);
                if (k.t != J::Str) throw Bad("object key is not a string");
                ws();
                if (i_ >= s_.size() || s_[i_] != ':') throw Bad("expected ':'");
                ++i_;
                v.o.emplace_back(k.s, value(depth + 1));
                ws();
                if (i_ < s_.size() && s_[i_] == ',') {
                    ++i_;
                    continue;
                }
                if (i_ < s_.size() && s_[i_] == '}') {
                    ++i_;
                    return v;
                }
                throw Bad("expected ',' or '}'");
            }
        }
        if (c == '[') {
            v.t = J::Arr;
            ++i_;
            ws();
            if (i_ < s_.size() && s_[i_] == ']') {
                ++i_;
                return v;
            }
            for (;;) {
                v.a.push_back(value(depth + 1));
                ws();
                if (i_ < s_.size() && s_[i_] == ',') {
                    ++i_;
                    continue;
                }
                if (i_ < s_.size() && s_[i_] == ']') {
                    ++i_;
                    return v;
                }
                throw Bad("expected ',' or ']'");
            }
        }
        if (c == '"') {
            v.t = J::Str;
            ++i_;
            while (i_ < s_.size() && s_[i_] != '"') {
                if (s_[i_] == '\\') throw Bad("escapes are not supported");
                v.s.push_back(s_[i_++]);
            }
            if (i_ >= s_.size()) throw Bad("unterminated string");
            ++i_;
            return v;
        }
        if (lit("true")) {
            v.t = J::Bool;
            v.b = true;
            return v;
        }
        if (lit("false")) {
            v.t = J::Bool;
            return v;
        }
        if (lit("null")) return v;
        size_t start = i_;
        while (i_ < s_.size() && std::strchr("+-0123456789.eE", s_[i_]) != nullptr) ++i_;
        std::string tok = s_.substr(start, i_ - start);
        if (tok.empty()) throw Bad("unexpected character");
        char* end = nullptr;
        v.t = J::Num;
        v.num = std::strtod(tok.c_str(), &end);
        if (end != tok.c_str() + tok.size()) throw Bad("bad number");
        if (tok.find_first_of(".eE") == std::string::npos) {
            errno = 0;
            v.i = std::strtoll(tok.c_str(), &end, 10);
            v.integral = errno == 0;
        }
        return v;
    }
    const std::string& s_;
    size_t i_ = 0;
};

const J& need(const J& ev, const char* k) {
    const J* v = ev.get(k);
    if (v == nullptr) throw Bad(std::string("missing \"") + k + "\"");
    return *v;
}
double num(const J& v, const char* what) {
    if (v.t != J::Num || !std::isfinite(v.num)) throw Bad(std::string(what) + " is not a number");
    return v.num;
}
long long integer(const J& v, const char* what, long long lo, long long hi) {
    if (v.t != J::Num || !v.integral || v.i < lo || v.i > hi)
        throw Bad(std::string(what) + " is not an integer in range");
    return v.i;
}
bool boolean(const J& v, const char* what) {
    if (v.t != J::Bool) throw Bad(std::string(what) + " is not true or false");
    return v.b;
}
Addr address(const J& v, const char* what) {
    Addr a;
    if (v.t != J::Str || !parse_addr(v.s, a)) throw Bad(std::string(what) + " is not an address");
    return a;
}
std::string unhex(const J& v, const char* what) {
    if (v.t != J::Str || v.s.size() % 2 != 0) throw Bad(std::string(what) + " is not hex");
    std::string out;
    out.reserve(v.s.size() / 2);
    for (size_t k = 0; k < v.s.size(); k += 2) {
        int hi = std::isxdigit((unsigned char)v.s[k]) ? 0 : -1;
        int lo = std::isxdigit((unsigned char)v.s[k + 1]) ? 0 : -1;
        if (hi < 0 || lo < 0) throw Bad(std::string(what) + " is not hex");
        out.push_back(char(std::stoi(v.s.substr(k, 2), nullptr, 16)));
    }
    return out;
}

Params params_of(const J* pj) {
    Params p;
    if (pj == nullptr) {
        p.derive();
        return p;
    }
    if (pj->t != J::Obj) throw Bad("params is not an object");
    double ts = 1.0;
    if (const J* t = pj->get("time_scale")) ts = num(*t, "time_scale");
    if (const J* prof = pj->get("profile")) {
        if (prof->t != J::Str || !profile(prof->s, ts, p)) throw Bad("unknown profile");
    }
    for (const auto& [k, v] : pj->o) {
        const char* n = k.c_str();
        auto dbl = [&](double& f) { f = num(v, n); };
        auto intg = [&](long long& f) { f = integer(v, n, -(1LL << 53), 1LL << 53); };
        auto opt = [&](std::optional<double>& f) {
            if (v.t == J::Null)
                f.reset();
            else
                f = num(v, n);
        };
        if (k == "profile") continue;
        else if (k == "time_scale") dbl(p.time_scale);
        else if (k == "active_route_timeout_ms") dbl(p.active_route_timeout_ms);
        else if (k == "allowed_hello_loss") intg(p.allowed_hello_loss);
        else if (k == "hello_interval_ms") dbl(p.hello_interval_ms);
        else if (k == "local_add_ttl") intg(p.local_add_ttl);
        else if (k == "net_diameter") intg(p.net_diameter);
        else if (k == "node_traversal_time_ms") dbl(p.node_traversal_time_ms);
        else if (k == "rerr_ratelimit") intg(p.rerr_ratelimit);
        else if (k == "rreq_retries") intg(p.rreq_retries);
        else if (k == "rreq_ratelimit") intg(p.rreq_ratelimit);
        else if (k == "timeout_buffer") intg(p.timeout_buffer);
        else if (k == "ttl_start") intg(p.ttl_start);
        else if (k == "ttl_increment") intg(p.ttl_increment);
        else if (k == "ttl_threshold") intg(p.ttl_threshold);
        else if (k == "delete_period_k") intg(p.delete_period_k);
        else if (k == "my_route_timeout_ms") opt(p.my_route_timeout_ms);
        else if (k == "blacklist_timeout_ms") opt(p.blacklist_timeout_ms);
        else if (k == "local_repair") p.local_repair = boolean(v, n);
        else if (k == "queue_len") intg(p.queue_len);
        else if (k == "gratuitous_rrep") p.gratuitous_rrep = boolean(v, n);
        else if (k == "dest_only") p.dest_only = boolean(v, n);
        else if (k == "route_table_limit") intg(p.route_table_limit);
        else if (k == "rreq_cache_limit") intg(p.rreq_cache_limit);
        else if (k == "neighbor_limit") intg(p.neighbor_limit);
        else if (k == "rreq_forward_ratelimit") intg(p.rreq_forward_ratelimit);
        else throw Bad("unknown parameter " + k);
    }
    if (!(p.time_scale > 0)) throw Bad("time_scale must be > 0");
    if (p.ttl_increment == 0) throw Bad("ttl_increment must not be 0");
    if (p.rreq_retries < 0 || p.rreq_retries > 1000) throw Bad("rreq_retries out of range");
    p.derive();
    return p;
}

// == canonical output (aodv/coretrace.py prints the same) ===================================
std::string g17(double x) {
    char buf[40];
    std::snprintf(buf, sizeof buf, "%.17g", x);
    return buf;
}
std::string q(Addr a) { return "\"" + addr_str(a) + "\""; }
std::string hex(const std::string& b) {
    static const char* d = "0123456789abcdef";
    std::string o;
    o.reserve(b.size() * 2);
    for (unsigned char c : b) {
        o.push_back(d[c >> 4]);
        o.push_back(d[c & 15]);
    }
    return o;
}
const char* tf(bool b) { return b ? "true" : "false"; }

std::string decoded(const Message& m) {
    std::string o = "[" + std::to_string(m.type);
    if (m.type == RREQ_TYPE) {
        const Rreq& r = m.rreq;
        o += "," + std::to_string(r.rreq_id) + "," + q(r.dest) + "," + std::to_string(r.dest_seq) +
             "," + q(r.orig) + "," + std::to_string(r.orig_seq) + "," +
             std::to_string(r.hop_count) + "," + tf(r.join) + "," + tf(r.repair) + "," +
             tf(r.gratuitous) + "," + tf(r.dest_only) + "," + tf(r.unknown_seq);
    } else if (m.type == RREP_TYPE) {
        const Rrep& r = m.rrep;
        o += "," + q(r.dest) + "," + std::to_string(r.dest_seq) + "," + q(r.orig) + "," +
             std::to_string(r.lifetime_ms) + "," + std::to_string(r.hop_count) + "," +
             tf(r.repair) + "," + tf(r.ack_required) + "," + std::to_string(r.prefix_size) + "," +
             (r.has_hello ? std::to_string(r.hello_interval_ms) : "null");
    } else if (m.type == RERR_TYPE) {
        o += ",[";
        bool first = true;
        for (const auto& [a, s] : m.rerr.unreachable) {
            o += (first ? "[" : ",[") + q(a) + "," + std::to_string(s) + "]";
            first = false;
        }
        o += std::string("],") + tf(m.rerr.no_delete);
    }
    return o + "]";
}

std::string packets(const std::vector<std::string>& ps) {
    std::string o = "[";
    for (size_t k = 0; k < ps.size(); ++k) o += (k ? ",\"" : "\"") + hex(ps[k]) + "\"";
    return o + "]";
}

std::string action(const Action& a) {
    switch (a.kind) {
        case Act::Unicast:
            return "{\"a\":\"unicast\",\"dst\":" + q(a.addr) + ",\"ttl\":" + std::to_string(a.ttl) +
                   ",\"msg\":\"" + hex(encode(a.msg)) + "\"}";
        case Act::Broadcast:
            return "{\"a\":\"broadcast\",\"ttl\":" + std::to_string(a.ttl) + ",\"msg\":\"" +
                   hex(encode(a.msg)) + "\"}";
        case Act::Install:
            return "{\"a\":\"install\",\"dest\":" + q(a.addr) + ",\"next_hop\":" + q(a.next_hop) +
                   ",\"hops\":" + std::to_string(a.hops) + "}";
        case Act::Delete:
            return "{\"a\":\"delete\",\"dest\":" + q(a.addr) + "}";
        case Act::Release:
            return "{\"a\":\"release\",\"dest\":" + q(a.addr) + ",\"packets\":" + packets(a.packets) + "}";
        case Act::Drop:
            return "{\"a\":\"drop\",\"dest\":" + q(a.addr) + ",\"packets\":" + packets(a.packets) + "}";
        case Act::Done:
            return "{\"a\":\"done\",\"dest\":" + q(a.addr) + ",\"ok\":" + tf(a.ok) +
                   ",\"latency\":" + g17(a.latency) + ",\"round_latency\":" + g17(a.round_latency) +
                   ",\"repair\":" + tf(a.repair) + "}";
    }
    return "{}";
}

std::string dump(const AodvCore& c) {
    std::string o = "{\"seq\":" + std::to_string(c.seq) + ",\"rreq_id\":" + std::to_string(c.rreq_id) +
                    ",\"routes\":[";
    bool first = true;
    for (const auto& e : c.table.peek_all()) {
        const Route& r = e.value;
        std::vector<std::string> pre;
        for (Addr a : r.precursors) pre.push_back(addr_str(a));
        std::sort(pre.begin(), pre.end());
        std::string ps = "[";
        for (size_t k = 0; k < pre.size(); ++k) ps += (k ? ",\"" : "\"") + pre[k] + "\"";
        ps += "]";
        o += std::string(first ? "" : ",") + "[" + q(r.dest) + "," + q(r.next_hop) + "," +
             std::to_string(r.hops) + "," + std::to_string(r.seq) + "," + tf(r.valid_seq) + "," +
             g17(r.lifetime) + "," + tf(r.valid) + "," + ps + "," + g17(r.active_until) + "]";
        first = false;
    }
    o += "],\"neighbors\":[";
    first = true;
    for (const auto& e : c.neighbors.all()) {
        const Neighbor& n = e.value;
        o += std::string(first ? "" : ",") + "[" + q(n.addr) + "," +
             (n.has_hello ? g17(n.last_hello) : "null") + "," + g17(n.last_heard) + "," +
             g17(n.timeout) + "]";
        first = false;
    }
    o += "],\"discoveries\":[";
    first = true;
    for (const auto& e : c.discoveries) {
        const Discovery& d = e.value;
        o += std::string(first ? "" : ",") + "[" + q(d.dest) + "," + std::to_string(d.ttl) + "," +
             g17(d.started) + "," + g17(d.deadline) + "," + g17(d.round_started) + "," +
             std::to_string(d.retries) + "," + tf(d.deferred) + "," +
             (d.is_repair ? std::to_string(d.repair_hops) : "null") + "]";
        first = false;
    }
    o += "],\"installed\":[";
    first = true;
    for (const auto& e : c.installed) {
        o += std::string(first ? "" : ",") + "[" + q(e.key) + "," + q(e.value.first) + "," +
             std::to_string(e.value.second) + "]";
        first = false;
    }
    o += "],\"reboot_until\":" + (c.rebooting ? g17(c.reboot_until) : std::string("null")) + "}";
    return o;
}

std::string end_line(double now, const AodvCore& c) {
    std::string o = "{\"now\":" + g17(now) + ",\"next\":" + g17(c.next_deadline()) + ",\"dropped\":{";
    bool first = true;
    for (const auto& [k, v] : c.dropped) {
        o += std::string(first ? "\"" : ",\"") + k + "\":" + std::to_string(v);
        first = false;
    }
    return o + "}}";
}

}  // namespace

int main() {
    std::ios::sync_with_stdio(false);
    std::unique_ptr<AodvCore> core;
    double last_now = 0;
    std::string line, out;
    while (std::getline(std::cin, line)) {
        if (line.empty()) continue;
        out.clear();
        try {
            J ev = Reader(line).parse();
            const J& kind = need(ev, "ev");
            if (kind.t != J::Str) throw Bad("\"ev\" is not a string");
            const std::string& k = kind.s;
            if (k == "init") {
                double now = num(need(ev, "now"), "now");
                Addr a = address(need(ev, "addr"), "addr");
                Params p = params_of(ev.get("params"));
                const J* rb = ev.get("rebooted");
                const J* sq = ev.get("seq");
                const J* ri = ev.get("rreq_id");
                core = std::make_unique<AodvCore>(
                    a, p, now, rb != nullptr && boolean(*rb, "rebooted"),
                    uint32_t(sq ? integer(*sq, "seq", 0, 0xFFFFFFFFLL) : 0),
                    uint32_t(ri ? integer(*ri, "rreq_id", 0, 0xFFFFFFFFLL) : 0));
                last_now = now;
                out += end_line(now, *core) + "\n";
            } else {
                if (!core) throw Bad("no init line yet");
                if (k == "dump") {
                    out += dump(*core) + "\n" + end_line(last_now, *core) + "\n";
                } else {
                    const J* nj = ev.get("now");
                    double now;
                    if (k == "timer" && (nj == nullptr || nj->t == J::Null)) {
                        double dl = core->next_deadline();
                        now = dl > last_now ? dl : last_now;
                    } else {
                        now = num(need(ev, "now"), "now");
                    }
                    std::vector<Action> acts;
                    if (k == "control") {
                        Addr src = address(need(ev, "src"), "src");
                        int ttl = int(integer(need(ev, "ttl"), "ttl", 0, 255));
                        std::string raw = unhex(need(ev, "bytes"), "bytes");
                        Message m;
                        if (decode(reinterpret_cast<const uint8_t*>(raw.data()), raw.size(), m)) {
                            out += "{\"decoded\":" + decoded(m) + "}\n";
                            acts = core->on_control(now, src, ttl, m);
                        } else {
                            out += "{\"malformed\":true}\n";
                        }
                    } else if (k == "no_route") {
                        Addr src = address(need(ev, "src"), "src");
                        Addr dst = address(need(ev, "dst"), "dst");
                        acts = core->on_no_route(now, src, dst, unhex(need(ev, "packet"), "packet"));
                    } else if (k == "route_used") {
                        acts = core->on_route_used(now, address(need(ev, "addr"), "addr"));
                    } else if (k == "routes_used") {
                        const J& l = need(ev, "addrs");
                        if (l.t != J::Arr) throw Bad("addrs is not a list");
                        std::vector<Addr> addrs;
                        for (const J& x : l.a) addrs.push_back(address(x, "addrs"));
                        acts = core->on_routes_used(now, addrs);
                    } else if (k == "link_lost") {
                        acts = core->on_link_lost(now, address(need(ev, "neighbor"), "neighbor"));
                    } else if (k == "timer") {
                        acts = core->on_timer(now);
                    } else {
                        throw Bad("unknown event " + k);
                    }
                    for (const Action& a : acts) out += action(a) + "\n";
                    last_now = now;
                    out += end_line(now, *core) + "\n";
                }
            }
        } catch (const std::exception& e) {
            out = std::string("{\"error\":\"") + e.what() + "\"}\n";
        }
        std::fwrite(out.data(), 1, out.size(), stdout);
        std::fflush(stdout);
    }
    return 0;
}
