// AODV wire format: see packet.h and aodv/packet.py (the reference).
#include "packet.h"

#include <cstdio>
#include <map>
#include <stdexcept>

namespace aodv {

std::string addr_str(Addr a) {
    char buf[16];
    std::snprintf(buf, sizeof buf, "%u.%u.%u.%u", (a >> 24) & 0xFF, (a >> 16) & 0xFF,
                  (a >> 8) & 0xFF, a & 0xFF);
    return buf;
}

bool parse_addr(const std::string& s, Addr& out) {
    Addr a = 0;
    size_t i = 0;
    for (int part = 0; part < 4; ++part) {
        if (part > 0) {
            if (i >= s.size() || s[i] != '.') return false;
            ++i;
        }
        size_t start = i;
        unsigned v = 0;
        while (i < s.size() && s[i] >= '0' && s[i] <= '9' && i - start < 3) {
            v = v * 10 + unsigned(s[i] - '0');
            ++i;
        }
        size_t len = i - start;
        if (len == 0 || v > 255 || (len > 1 && s[start] == '0')) return false;
        a = (a << 8) | v;
    }
    if (i != s.size()) return false;
    out = a;
    return true;
}

namespace {

void put8(std::string& o, unsigned v) { o.push_back(char(v & 0xFF)); }
void put32(std::string& o, uint32_t v) {
    put8(o, v >> 24);
    put8(o, v >> 16);
    put8(o, v >> 8);
    put8(o, v);
}
uint32_t get32(const uint8_t* p) {
    return (uint32_t(p[0]) << 24) | (uint32_t(p[1]) << 16) | (uint32_t(p[2]) << 8) | p[3];
}
void check8(const char* name, int v) {
    if (v < 0 || v > 255) throw std::invalid_argument(std::string(name) + " does not fit");
}

constexpr size_t RREQ_SIZE = 24, RREP_SIZE = 20, RERR_HEAD = 4, RERR_DEST = 8;

// Type-Length-Data extensions (RFC 3561 section 9) filling [p, p + n) exactly; the first
// of each type is kept (aodv/packet.py `_extensions`).
bool extensions(const uint8_t* p, size_t n, std::map<int, std::pair<size_t, size_t>>& exts,
                std::string* why) {
    size_t i = 0;
    while (i < n) {
        if (n - i < 2) {
            if (why) *why = "truncated extension header";
            return false;
        }
        int etype = p[i], elen = p[i + 1];
        if (etype == 0) {
            if (why) *why = "extension type 0 is reserved";
            return false;
        }
        if (etype >= 128 && etype != EXT_HELLO_INTERVAL && etype != EXT_HELLO_INTERVAL_WIRESHARK) {
            // RFC 3561 9: "Extensions with types between 128 and 255 may NOT be skipped."
            if (why) *why = "extension type >= 128 is unknown and may not be skipped";
            return false;
        }
        if (n - i - 2 < size_t(elen)) {
            if (why) *why = "extension claims more bytes than are left";
            return false;
        }
        exts.emplace(etype, std::make_pair(i + 2, size_t(elen)));
        i += 2 + size_t(elen);
    }
    return true;
}

}  // namespace

std::string encode(const Message& m) {
    std::string o;
    switch (m.type) {
        case RREQ_TYPE: {
            const Rreq& r = m.rreq;
            check8("hop_count", r.hop_count);
            o.reserve(RREQ_SIZE);
            put8(o, RREQ_TYPE);
            put8(o, (r.join ? 0x80 : 0) | (r.repair ? 0x40 : 0) | (r.gratuitous ? 0x20 : 0) |
                        (r.dest_only ? 0x10 : 0) | (r.unknown_seq ? 0x08 : 0));
            put8(o, 0);
            put8(o, unsigned(r.hop_count));
            put32(o, r.rreq_id);
            put32(o, r.dest);
            put32(o, r.dest_seq);
            put32(o, r.orig);
            put32(o, r.orig_seq);
            return o;
        }
        case RREP_TYPE: {
            const Rrep& r = m.rrep;
            if (r.prefix_size < 0 || r.prefix_size > 31)
                throw std::invalid_argument("prefix_size does not fit in 5 bits");
            check8("hop_count", r.hop_count);
            o.reserve(RREP_SIZE + 6);
            put8(o, RREP_TYPE);
            put8(o, (r.repair ? 0x80 : 0) | (r.ack_required ? 0x40 : 0));
            put8(o, unsigned(r.prefix_size));
            put8(o, unsigned(r.hop_count));
            put32(o, r.dest);
            put32(o, r.dest_seq);
            put32(o, r.orig);
            put32(o, r.lifetime_ms);
            if (r.has_hello) {
                put8(o, EXT_HELLO_INTERVAL);
                put8(o, 4);
                put32(o, r.hello_interval_ms);
            }
            return o;
        }
        case RERR_TYPE: {
            const Rerr& r = m.rerr;
            size_t n = r.unreachable.size();
            if (n < 1 || n > 255) throw std::invalid_argument("a RERR carries 1..255 destinations");
            put8(o, RERR_TYPE);
            put8(o, r.no_delete ? 0x80 : 0);
            put8(o, 0);
            put8(o, unsigned(n));
            for (const auto& [a, s] : r.unreachable) {
                put32(o, a);
                put32(o, s);
            }
            return o;
        }
        case RREP_ACK_TYPE:
            put8(o, RREP_ACK_TYPE);
            put8(o, 0);
            return o;
    }
    throw std::invalid_argument("unknown message type");
}

bool decode(const uint8_t* d, size_t n, Message& out, std::string* why) {
    if (n == 0) {
        if (why) *why = "empty datagram";
        return false;
    }
    std::map<int, std::pair<size_t, size_t>> exts;
    int mtype = d[0];
    if (mtype == RREQ_TYPE) {
        if (n < RREQ_SIZE) {
            if (why) *why = "short RREQ";
            return false;
        }
        if (n > RREQ_SIZE && !extensions(d + RREQ_SIZE, n - RREQ_SIZE, exts, why)) return false;
        Rreq r;
        int f = d[1];
        r.join = f & 0x80;
        r.repair = f & 0x40;
        r.gratuitous = f & 0x20;
        r.dest_only = f & 0x10;
        r.unknown_seq = f & 0x08;
        r.hop_count = d[3];
        r.rreq_id = get32(d + 4);
        r.dest = get32(d + 8);
        r.dest_seq = get32(d + 12);
        r.orig = get32(d + 16);
        r.orig_seq = get32(d + 20);
        out = Message::of(r);
        return true;
    }
    if (mtype == RREP_TYPE) {
        if (n < RREP_SIZE) {
            if (why) *why = "short RREP";
            return false;
        }
        Rrep r;
        if (n > RREP_SIZE) {
            if (!extensions(d + RREP_SIZE, n - RREP_SIZE, exts, why)) return false;
            // Type 1 first, then Wireshark's 2 (aodv/packet.py `_hello_interval`).
            for (int etype : {EXT_HELLO_INTERVAL, EXT_HELLO_INTERVAL_WIRESHARK}) {
                auto it = exts.find(etype);
                if (it == exts.end()) continue;
                if (it->second.second != 4) {
                    if (why) *why = "hello interval extension not of 4 bytes";
                    return false;
                }
                r.has_hello = true;
                r.hello_interval_ms = get32(d + RREP_SIZE + it->second.first);
                break;
            }
        }
        int f = d[1];
        r.repair = f & 0x80;
        r.ack_required = f & 0x40;
        r.prefix_size = d[2] & 0x1F;
        r.hop_count = d[3];
        r.dest = get32(d + 4);
        r.dest_seq = get32(d + 8);
        r.orig = get32(d + 12);
        r.lifetime_ms = get32(d + 16);
        out = Message::of(r);
        return true;
    }
    if (mtype == RERR_TYPE) {
        if (n < RERR_HEAD) {
            if (why) *why = "short RERR";
            return false;
        }
        size_t count = d[3];
        if (count == 0) {
            if (why) *why = "RERR with DestCount 0";
            return false;
        }
        size_t end = RERR_HEAD + count * RERR_DEST;
        if (n < end) {
            if (why) *why = "RERR shorter than its DestCount";
            return false;
        }
        if (!extensions(d + end, n - end, exts, why)) return false;
        Rerr r;
        r.no_delete = d[1] & 0x80;
        r.unreachable.reserve(count);
        for (size_t k = 0; k < count; ++k) {
            const uint8_t* p = d + RERR_HEAD + k * RERR_DEST;
            r.unreachable.emplace_back(get32(p), get32(p + 4));
        }
        out = Message::of(r);
        return true;
    }
    if (mtype == RREP_ACK_TYPE) {
        if (n < 2) {
            if (why) *why = "RREP-ACK of 1 byte";
            return false;
        }
        if (!extensions(d + 2, n - 2, exts, why)) return false;
        out = Message::ack();
        return true;
    }
    if (why) *why = "unknown AODV message type";
    return false;
}

bool is_hello(const Message& m, Addr src) {
    return m.type == RREP_TYPE && m.rrep.hop_count == 0 && m.rrep.dest == src &&
           m.rrep.orig == src;
}

}  // namespace aodv
