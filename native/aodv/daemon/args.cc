// See args.h. The order of the checks is argparse's: options as they come (each value
// converted and checked when it is read), then the required ones, then build_params.
#include "args.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <map>

#include "../packet.h"
#include "aodv_consts.h"

namespace aodv {

namespace {

// Underscores only between digits (Python's numeric literals); removed.
bool no_underscores(const std::string& t, std::string& out) {
    out.clear();
    for (size_t k = 0; k < t.size(); ++k) {
        if (t[k] != '_') {
            out += t[k];
            continue;
        }
        if (k == 0 || k + 1 >= t.size() || !isdigit((unsigned char)t[k - 1]) ||
            !isdigit((unsigned char)t[k + 1]))
            return false;
    }
    return true;
}

std::string lower(std::string t) {
    for (auto& c : t) c = char(tolower((unsigned char)c));
    return t;
}

// Python's repr of a str, as argparse quotes a value in its messages.
std::string py_quote(const std::string& t) {
    bool sq = t.find('\'') != std::string::npos && t.find('"') == std::string::npos;
    char q = sq ? '"' : '\'';
    std::string out(1, q);
    for (unsigned char c : t) {
        if (c == '\\') out += "\\\\";
        else if (c == (unsigned char)q) { out += '\\'; out += char(c); }
        else if (c == '\n') out += "\\n";
        else if (c == '\t') out += "\\t";
        else if (c == '\r') out += "\\r";
        else if (c < 0x20 || c == 0x7f) {
            char b[8];
            snprintf(b, sizeof b, "\\x%02x", c);
            out += b;
        } else out += char(c);
    }
    return out + q;
}

// common.argtypes.number's "%g" of a bound.
std::string g_fmt(double x) {
    char b[32];
    snprintf(b, sizeof b, "%g", x);
    return b;
}

bool looks_negative(const std::string& t) {
    // argparse's _negative_number_matcher: '^-\d+$|^-\d*\.\d+$'
    if (t.size() < 2 || t[0] != '-') return false;
    size_t dot = t.find('.');
    for (size_t k = 1; k < t.size(); ++k)
        if (k != dot && !isdigit((unsigned char)t[k])) return false;
    if (dot == std::string::npos) return true;
    return t.find('.', dot + 1) == std::string::npos && dot + 1 < t.size();
}

// ipaddress.IPv4Network(text) (strict): "A.B.C.D[/prefix|/netmask|/hostmask]".
bool dotted(const std::string& t, uint32_t& out) {
    // ipaddress: four decimal octets, 1-3 digits, no leading zeros, each <= 255.
    uint32_t v = 0;
    int parts = 0;
    size_t k = 0;
    while (true) {
        size_t start = k;
        while (k < t.size() && isdigit((unsigned char)t[k])) ++k;
        size_t n = k - start;
        if (n == 0 || n > 3 || (n > 1 && t[start] == '0')) return false;
        int oct = atoi(t.substr(start, n).c_str());
        if (oct > 255) return false;
        v = (v << 8) | uint32_t(oct);
        ++parts;
        if (k == t.size()) break;
        if (t[k] != '.' || parts == 4) return false;
        ++k;
    }
    if (parts != 4) return false;
    out = v;
    return true;
}

bool contiguous_prefix(uint32_t mask, int& plen) {
    int n = 0;
    while (n < 32 && (mask & (0x80000000u >> n))) ++n;
    uint32_t expect = n == 0 ? 0 : ~uint32_t(0) << (32 - n);
    if (mask != expect) return false;
    plen = n;
    return true;
}

bool network(const std::string& text, Args& a, std::string& err) {
    size_t slash = text.find('/');
    std::string addr = text.substr(0, slash);
    std::string mask = slash == std::string::npos ? "32" : text.substr(slash + 1);
    if (slash != std::string::npos && text.find('/', slash + 1) != std::string::npos) {
        err = "Only one '/' permitted in " + py_quote(text);
        return false;
    }
    uint32_t ip;
    if (!dotted(addr, ip)) {
        err = py_quote(addr) + " does not appear to be an IPv4 address";
        return false;
    }
    int plen = -1;
    bool digits = !mask.empty();
    for (char c : mask) digits = digits && (unsigned char)c < 128 && isdigit((unsigned char)c);
    if (digits) {
        if (mask.size() <= 3) plen = atoi(mask.c_str());
        if (plen > 32) plen = -1;
    } else {
        uint32_t m;
        if (dotted(mask, m) && !contiguous_prefix(m, plen)) {
            plen = -1;
            contiguous_prefix(~m, plen) || (plen = -1);  // a host mask
        }
    }
    if (plen < 0) {
        err = py_quote(mask) + " is not a valid netmask";
        return false;
    }
    uint32_t m = plen == 0 ? 0 : ~uint32_t(0) << (32 - plen);
    if (ip & ~m) {
        err = text + " has host bits set";
        return false;
    }
    a.net_addr = ip;
    a.net_mask = m;
    a.net_prefix = plen;
    a.net = addr_str(ip) + "/" + std::to_string(plen);
    return true;
}

}  // namespace

namespace {
// Python's int() and float() read their text as ASCII first: blanks (str.isspace) around it
// stripped, decimal digits of every script (category Nd) as 0-9; any other character beyond
// ASCII fails. false for text that is not UTF-8 (Python's argv holds it as lone surrogates,
// which neither takes).
bool to_ascii(const std::string& text, std::string& out) {
    std::vector<unsigned> cps;
    for (size_t k = 0; k < text.size();) {
        unsigned char c = (unsigned char)text[k];
        int len = c < 0x80 ? 1 : c >= 0xF0 && c < 0xF5 ? 4 : c >= 0xE0 ? 3 : c >= 0xC2 && c < 0xE0 ? 2 : 0;
        if (len == 0 || k + size_t(len) > text.size()) return false;
        unsigned cp = len == 1 ? c : len == 2 ? c & 31 : len == 3 ? c & 15 : c & 7;
        for (int j = 1; j < len; ++j) {
            unsigned char d = (unsigned char)text[k + size_t(j)];
            if ((d & 0xC0) != 0x80) return false;
            cp = (cp << 6) | (d & 0x3F);
        }
        if ((len == 3 && cp < 0x800) || (len == 4 && (cp < 0x10000 || cp > 0x10FFFF)) ||
            (cp >= 0xD800 && cp < 0xE000))
            return false;
        cps.push_back(cp);
        k += size_t(len);
    }
    auto space = [](unsigned cp) {
        for (unsigned s : gen::SPACES)
            if (s == cp) return true;
        return false;
    };
    // ASCII stays as it is; blanks beyond ASCII become ' ', digits beyond it 0-9 (CPython's
    // _PyUnicode_TransformDecimalAndSpaceToASCII); then ASCII blanks around are stripped.
    std::string t;
    for (unsigned cp : cps) {
        if (cp < 0x80) {
            t += char(cp);
            continue;
        }
        if (space(cp)) {
            t += ' ';
            continue;
        }
        bool digit = false;
        for (unsigned z : gen::DIGIT_ZEROS)
            if (cp >= z && cp < z + 10) {
                t += char('0' + (cp - z));
                digit = true;
                break;
            }
        if (!digit) return false;
    }
    auto blank = [](char c) { return c == ' ' || (c >= '\t' && c <= '\r'); };
    size_t a = 0, b = t.size();
    while (a < b && blank(t[a])) ++a;
    while (b > a && blank(t[b - 1])) --b;
    out = t.substr(a, b - a);
    return true;
}
}  // namespace

bool py_float(const std::string& text, double& out) {
    std::string t, u;
    if (!to_ascii(text, t)) return false;
    std::string l = lower(t);
    std::string body = (!l.empty() && (l[0] == '+' || l[0] == '-')) ? l.substr(1) : l;
    double sign = (!l.empty() && l[0] == '-') ? -1.0 : 1.0;
    if (body == "inf" || body == "infinity") { out = sign * INFINITY; return true; }
    if (body == "nan") { out = NAN; return true; }
    if (!no_underscores(t, u) || u.empty()) return false;
    // [sign] (digits [. digits] | . digits) [e [sign] digits]: no hex, no spaces inside.
    size_t k = 0;
    if (u[k] == '+' || u[k] == '-') ++k;
    size_t m = k;
    while (k < u.size() && isdigit((unsigned char)u[k])) ++k;
    size_t ints = k - m, fr = 0;
    if (k < u.size() && u[k] == '.') {
        ++k;
        size_t f0 = k;
        while (k < u.size() && isdigit((unsigned char)u[k])) ++k;
        fr = k - f0;
    }
    if (ints + fr == 0) return false;
    if (k < u.size() && (u[k] == 'e' || u[k] == 'E')) {
        ++k;
        if (k < u.size() && (u[k] == '+' || u[k] == '-')) ++k;
        size_t e0 = k;
        while (k < u.size() && isdigit((unsigned char)u[k])) ++k;
        if (k == e0) return false;
    }
    if (k != u.size()) return false;
    out = strtod(u.c_str(), nullptr);
    return true;
}

bool py_int(const std::string& text, long long& out) {
    std::string t, u;
    if (!to_ascii(text, t) || !no_underscores(t, u) || u.empty()) return false;
    size_t k = (u[0] == '+' || u[0] == '-') ? 1 : 0;
    if (k == u.size()) return false;
    for (size_t j = k; j < u.size(); ++j)
        if (!isdigit((unsigned char)u[j])) return false;
    // Python's int has no bound; past 2**53 a count or a limit is as good as infinite to
    // the core (and its sums stay in range): saturated there.
    constexpr long long SAT = 1LL << 53;
    size_t first = u.find_first_not_of('0', k);
    bool neg = u[0] == '-';
    if (first != std::string::npos && u.size() - first > 18) {
        out = neg ? -SAT : SAT;
        return true;
    }
    out = strtoll(u.c_str(), nullptr, 10);
    out = std::max(-SAT, std::min(SAT, out));
    return true;
}

std::string usage_text() {
    std::string u =
        "usage: tb-aodv [-h] --robot ROBOT [--iface IFACE] [--time-scale TIME_SCALE]\n"
        "               [--profile {ns3,rfc}] [--no-local-repair] [--set NAME=VALUE]\n"
        "               [--stats PATH] [--stats-period SECONDS] [--state PATH]\n"
        "               [--log-level {debug,info,warning,error}] [--net NET]\n"
        "               [--netns NAME]\n\n"
        "AODV (RFC 3561) routing daemon for one robot's network namespace, compiled\n"
        "(the command line of python -m aodv).\n\noptions:\n";
    for (const auto& o : gen::OPTIONS) {
        u += "  ";
        u += o.flag;
        if (o.fallback) {
            u += " (default ";
            u += o.fallback;
            u += ")";
        }
        if (o.required) u += " (required)";
        u += "\n";
    }
    return u;
}

namespace {
// The options `name` names exactly or as a unique prefix (argparse's _get_option_tuples).
std::vector<const gen::Option*> matches(const std::string& name) {
    std::vector<const gen::Option*> hits;
    if (name == "-h" || name == "--help") {
        for (const auto& o : gen::OPTIONS)
            if (o.kind == gen::OptKind::Help) return {&o};
    }
    if (name.rfind("--", 0) != 0 || name.size() <= 2) return hits;
    for (const auto& o : gen::OPTIONS) {
        if (name == o.flag) return {&o};
        if (std::string(o.flag).rfind(name, 0) == 0) hits.push_back(&o);
    }
    return hits;
}

// argparse's _parse_optional: true when `arg` is taken as an option (or an unknown one),
// false when it is a value.
bool option_like(const std::string& arg) {
    if (arg.empty() || arg[0] != '-' || arg.size() == 1) return false;
    std::string name = arg.substr(0, arg.find('='));
    if (!matches(arg).empty() || !matches(name).empty()) return true;
    if (looks_negative(arg)) return false;
    if (arg.find(' ') != std::string::npos) return false;
    return true;
}
}  // namespace

bool parse_args(int argc, char** argv, Args& a, std::string& err, bool& help) {
    help = false;
    std::map<std::string, std::string> value;  // dest -> text, defaults first
    for (const auto& o : gen::OPTIONS)
        if (o.kind == gen::OptKind::Value && o.fallback) value[o.dest] = o.fallback;
    std::map<std::string, bool> seen;
    std::vector<std::string> extra;
    bool time_scale_given = false;
    bool stats_period_given = false;

    auto check = [&](const gen::Option& o, const std::string& v) -> bool {
        std::string where = std::string("argument ") + o.flag + ": ";
        if (o.n_choices > 0) {
            bool ok = false;
            for (int c = 0; c < o.n_choices; ++c) ok = ok || v == o.choices[c];
            if (!ok) {
                err = where + "invalid choice: " + py_quote(v) + " (choose from ";
                for (int c = 0; c < o.n_choices; ++c)
                    err += (c ? ", " : "") + py_quote(o.choices[c]);
                err += ")";
                return false;
            }
        }
        if (strcmp(o.dest, "time_scale") == 0) {
            double x;
            if (!py_float(v, x)) {
                err = where + "time scale must be a number, not " + py_quote(v);
                return false;
            }
            if (!std::isfinite(x)) {
                err = where + "time scale must be finite, not " + py_quote(v);
                return false;
            }
            if (!(x > 0)) {
                err = where + "time scale must be greater than " + g_fmt(0) + ", not " + v;
                return false;
            }
            a.time_scale = x;
            time_scale_given = true;
        }
        if (strcmp(o.dest, "stats_period") == 0) {  // number(float, ..., minimum=0)
            double x;
            if (!py_float(v, x)) {
                err = where + "stats period must be a number, not " + py_quote(v);
                return false;
            }
            if (!std::isfinite(x)) {
                err = where + "stats period must be finite, not " + py_quote(v);
                return false;
            }
            if (x < 0) {
                err = where + "stats period must not be negative, not " + v;
                return false;
            }
            a.stats_period = x > 0 ? x : INFINITY;
            stats_period_given = true;
        }
        if (strcmp(o.dest, "net") == 0) {
            std::string why;
            if (!network(v, a, why)) {
                err = where + why;
                return false;
            }
        }
        if (strcmp(o.dest, "netns") == 0 && (v.empty() || v == "." || v == ".." ||
                                             v.find('/') != std::string::npos)) {
            err = where + "not a network namespace name: " + py_quote(v);  // aodv.__main__
            return false;
        }
        return true;
    };

    bool only_positional = false;
    for (int i = 1; i < argc; ++i) {
        std::string arg = argv[i];
        // After "--" everything is a positional argument, and this parser takes none: all
        // of it, "--" included, is unrecognized (argparse, Python 3.11).
        if (arg == "--") only_positional = true;
        if (only_positional || !option_like(arg)) {
            extra.push_back(arg);
            continue;
        }
        std::string name = arg, explicit_value;
        bool has_explicit = false;
        auto hits = matches(arg);
        if (hits.empty()) {
            size_t eq = arg.find('=');
            if (eq != std::string::npos) {
                name = arg.substr(0, eq);
                explicit_value = arg.substr(eq + 1);
                has_explicit = true;
                hits = matches(name);
            }
        }
        if (hits.size() > 1) {
            err = "ambiguous option: " + name + " could match ";
            for (size_t h = 0; h < hits.size(); ++h)
                err += (h ? ", " : "") + std::string(hits[h]->flag);
            return false;
        }
        if (hits.empty()) {
            extra.push_back(arg);
            continue;
        }
        const gen::Option* opt = hits[0];
        switch (opt->kind) {
            case gen::OptKind::Help:
            case gen::OptKind::Switch:
                if (has_explicit) {
                    err = std::string("argument ") + (opt->kind == gen::OptKind::Help ? "-h/" : "") +
                          opt->flag + ": ignored explicit argument " + py_quote(explicit_value);
                    return false;
                }
                if (opt->kind == gen::OptKind::Help) {
                    help = true;
                    return true;
                }
                a.no_local_repair = true;
                break;
            case gen::OptKind::Append:
            case gen::OptKind::Value: {
                std::string v;
                if (has_explicit) {
                    v = explicit_value;
                } else if (i + 1 < argc && !option_like(argv[i + 1]) &&
                           strcmp(argv[i + 1], "--") != 0) {
                    v = argv[++i];
                } else {
                    err = std::string("argument ") + opt->flag + ": expected one argument";
                    return false;
                }
                if (!check(*opt, v)) return false;
                if (opt->kind == gen::OptKind::Append) a.sets.push_back(v);
                else value[opt->dest] = v;
                break;
            }
        }
        seen[opt->dest] = true;
    }
    std::string missing;
    for (const auto& o : gen::OPTIONS)
        if (o.required && !seen[o.dest]) missing += (missing.empty() ? "" : ", ") + std::string(o.flag);
    if (!missing.empty()) {
        err = "the following arguments are required: " + missing;
        return false;
    }
    if (!extra.empty()) {
        err = "unrecognized arguments:";
        for (auto& e : extra) err += " " + e;
        return false;
    }
    a.robot = value["robot"];
    a.iface = value["iface"];
    a.profile = value["profile"];
    a.log_level = value["log_level"];
    a.has_stats = !value["stats"].empty();  // Python: `if self.stats_path`
    a.has_state = !value["state"].empty();
    a.stats = value["stats"];
    a.state = value["state"];
    a.netns = value["netns"];
    if (!time_scale_given && !py_float(value["time_scale"], a.time_scale)) a.time_scale = 1.0;
    if (!stats_period_given && !py_float(value["stats_period"], a.stats_period))
        a.stats_period = 1.0;
    if (!seen["net"] && !network(value["net"], a, err)) return false;
    return true;
}

namespace {
using Setter = std::function<void(Params&, double)>;
// Every field `--set` takes, by its Params name (build/gen/aodv_consts.h lists the names the
// Python dataclass has: a field missing here is refused with a line saying so).
const std::map<std::string, Setter>& setters() {
    static const std::map<std::string, Setter> s = {
        {"active_route_timeout_ms", [](Params& p, double v) { p.active_route_timeout_ms = v; }},
        {"allowed_hello_loss", [](Params& p, double v) { p.allowed_hello_loss = (long long)v; }},
        {"hello_interval_ms", [](Params& p, double v) { p.hello_interval_ms = v; }},
        {"local_add_ttl", [](Params& p, double v) { p.local_add_ttl = (long long)v; }},
        {"net_diameter", [](Params& p, double v) { p.net_diameter = (long long)v; }},
        {"node_traversal_time_ms", [](Params& p, double v) { p.node_traversal_time_ms = v; }},
        {"rerr_ratelimit", [](Params& p, double v) { p.rerr_ratelimit = (long long)v; }},
        {"rreq_retries", [](Params& p, double v) { p.rreq_retries = (long long)v; }},
        {"rreq_ratelimit", [](Params& p, double v) { p.rreq_ratelimit = (long long)v; }},
        {"timeout_buffer", [](Params& p, double v) { p.timeout_buffer = (long long)v; }},
        {"ttl_start", [](Params& p, double v) { p.ttl_start = (long long)v; }},
        {"ttl_increment", [](Params& p, double v) { p.ttl_increment = (long long)v; }},
        {"ttl_threshold", [](Params& p, double v) { p.ttl_threshold = (long long)v; }},
        {"delete_period_k", [](Params& p, double v) { p.delete_period_k = (long long)v; }},
        {"my_route_timeout_ms", [](Params& p, double v) { p.my_route_timeout_ms = v; }},
        {"blacklist_timeout_ms", [](Params& p, double v) { p.blacklist_timeout_ms = v; }},
        {"local_repair", [](Params& p, double v) { p.local_repair = v != 0; }},
        {"queue_len", [](Params& p, double v) { p.queue_len = (long long)v; }},
        {"gratuitous_rrep", [](Params& p, double v) { p.gratuitous_rrep = v != 0; }},
        {"dest_only", [](Params& p, double v) { p.dest_only = v != 0; }},
        {"route_table_limit", [](Params& p, double v) { p.route_table_limit = (long long)v; }},
        {"rreq_cache_limit", [](Params& p, double v) { p.rreq_cache_limit = (long long)v; }},
        {"neighbor_limit", [](Params& p, double v) { p.neighbor_limit = (long long)v; }},
        {"rreq_forward_ratelimit",
         [](Params& p, double v) { p.rreq_forward_ratelimit = (long long)v; }},
    };
    return s;
}

std::string ms_text(const Params& p, double seconds) { return std::to_string(p.ms(seconds)); }
}  // namespace

std::vector<std::string> problems(const Params& p) {
    std::vector<std::string> out;
    if (!(p.active_route_timeout_ms > 0)) out.push_back("active_route_timeout_ms must be > 0");
    if (!(p.hello_interval_ms > 0)) out.push_back("hello_interval_ms must be > 0");
    if (!(p.node_traversal_time_ms > 0)) out.push_back("node_traversal_time_ms must be > 0");
    if (p.allowed_hello_loss < 1) out.push_back("allowed_hello_loss must be >= 1");
    if (p.ttl_start < 1) out.push_back("ttl_start must be >= 1");
    if (p.ttl_increment < 1) out.push_back("ttl_increment must be >= 1");
    if (p.delete_period_k < 1) out.push_back("delete_period_k must be >= 1");
    if (!(p.ttl_start <= p.ttl_threshold && p.ttl_threshold <= p.net_diameter &&
          p.net_diameter <= MAX_TTL))
        out.push_back("TTL_START <= TTL_THRESHOLD <= NET_DIAMETER <= 255 must hold (" +
                      std::to_string(p.ttl_start) + ", " + std::to_string(p.ttl_threshold) +
                      ", " + std::to_string(p.net_diameter) + ")");
    if (p.my_route_timeout < 2 * p.path_discovery_time - 1e-9)
        out.push_back("MY_ROUTE_TIMEOUT (" + ms_text(p, p.my_route_timeout) +
                      " ms) must be at least 2 * PATH_DISCOVERY_TIME (" +
                      ms_text(p, 2 * p.path_discovery_time) + " ms)");
    if (p.delete_period < p.neighbor_timeout)
        out.push_back("DELETE_PERIOD must be at least ALLOWED_HELLO_LOSS * HELLO_INTERVAL");
    if (p.rreq_ratelimit < 1) out.push_back("rreq_ratelimit must be >= 1");
    if (p.rerr_ratelimit < 1) out.push_back("rerr_ratelimit must be >= 1");
    if (p.rreq_forward_ratelimit < 1) out.push_back("rreq_forward_ratelimit must be >= 1");
    if (p.queue_len < 1) out.push_back("queue_len must be >= 1");
    if (p.route_table_limit < 16) out.push_back("route_table_limit must be >= 16");
    if (p.rreq_cache_limit < 16) out.push_back("rreq_cache_limit must be >= 16");
    if (p.neighbor_limit < 16) out.push_back("neighbor_limit must be >= 16");
    return out;
}

bool build_params(const Args& a, Params& p, std::string& err) {
    if (!profile(a.profile, a.time_scale, p)) {
        err = "unknown AODV profile " + py_quote(a.profile);
        return false;
    }
    if (a.no_local_repair) p.local_repair = false;
    for (const auto& item : a.sets) {
        size_t eq = item.find('=');
        std::string name = item.substr(0, eq);
        std::string text = eq == std::string::npos ? "" : item.substr(eq + 1);
        const gen::ParamField* f = nullptr;
        for (const auto& pf : gen::PARAMS)
            if (name == pf.name) f = &pf;
        if (eq == std::string::npos || f == nullptr) {
            err = "--set " + py_quote(item) + ": not NAME=VALUE with NAME a field of Params";
            return false;
        }
        auto it = setters().find(name);
        if (it == setters().end()) {
            err = "--set " + py_quote(item) + ": " + name + " is not known to tb-aodv";
            return false;
        }
        double v = 0;
        bool ok;
        const char* kind;
        if (f->kind == gen::ParamKind::Bool) {
            kind = "bool";
            ok = text == "true" || text == "false";
            v = text == "true";
        } else if (f->kind == gen::ParamKind::Int) {
            kind = "int";
            long long x = 0;
            ok = py_int(text, x);
            v = double(x);
        } else {
            kind = "float";
            ok = py_float(text, v);
        }
        if (!ok) {
            err = "--set " + py_quote(item) + ": " + name + " takes " + kind;
            return false;
        }
        it->second(p, v);
    }
    // Params.problems() reads no blacklist timeout, whose derivation divides by
    // TTL_INCREMENT: derived with 1 in its place when it is 0, so the check can say so.
    long long increment = p.ttl_increment;
    if (increment == 0) p.ttl_increment = 1;
    p.derive();
    p.ttl_increment = increment;
    auto bad = problems(p);
    if (!bad.empty()) {
        err = "parameters break RFC 3561: ";
        for (size_t k = 0; k < bad.size(); ++k) err += (k ? "; " : "") + bad[k];
        return false;
    }
    return true;
}

}  // namespace aodv
