// AODV wire format (RFC 3561 section 5) and IPv4 addresses, as aodv/packet.py has them.
//
// Messages are plain structs; encode() lays one out in network byte order exactly as the
// RFC figures (and aodv/packet.py) do; decode() parses one UDP payload and returns false
// (with a reason) on anything aodv/packet.py rejects with MalformedPacket: empty datagram,
// unknown type, short message, RERR with DestCount 0 or too few bytes, an extension of type
// 0, of an unknown type >= 128 (RFC 3561 section 9: "may NOT be skipped"), or truncated, and
// a Hello Interval extension whose length is not 4. Reserved bits are sent as 0 and ignored.
// The Hello Interval extension is sent as type 1 (RFC 9.1, IANA); Wireshark's 2 is accepted.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace aodv {

// An IPv4 address in host byte order (10.0.0.1 is 0x0A000001).
using Addr = uint32_t;

std::string addr_str(Addr a);
// Strict dotted quad (what inet_pton accepts); false otherwise.
bool parse_addr(const std::string& s, Addr& out);

constexpr int RREQ_TYPE = 1;
constexpr int RREP_TYPE = 2;
constexpr int RERR_TYPE = 3;
constexpr int RREP_ACK_TYPE = 4;
constexpr int EXT_HELLO_INTERVAL = 1;
constexpr int EXT_HELLO_INTERVAL_WIRESHARK = 2;

struct Rreq {
    uint32_t rreq_id = 0;
    Addr dest = 0;
    uint32_t dest_seq = 0;
    Addr orig = 0;
    uint32_t orig_seq = 0;
    int hop_count = 0;
    bool join = false, repair = false, gratuitous = false, dest_only = false,
         unknown_seq = false;
};

struct Rrep {
    Addr dest = 0;
    uint32_t dest_seq = 0;
    Addr orig = 0;
    uint32_t lifetime_ms = 0;
    int hop_count = 0;
    bool repair = false, ack_required = false;
    int prefix_size = 0;
    bool has_hello = false;  // a Hello Interval extension (Python: hello_interval_ms not None)
    uint32_t hello_interval_ms = 0;
};

struct Rerr {
    std::vector<std::pair<Addr, uint32_t>> unreachable;
    bool no_delete = false;
};

// One control message: `type` says which member is meaningful (RREP-ACK has none).
struct Message {
    int type = RREQ_TYPE;
    Rreq rreq;
    Rrep rrep;
    Rerr rerr;

    static Message of(const Rreq& m) { Message x; x.type = RREQ_TYPE; x.rreq = m; return x; }
    static Message of(const Rrep& m) { Message x; x.type = RREP_TYPE; x.rrep = m; return x; }
    static Message of(const Rerr& m) { Message x; x.type = RERR_TYPE; x.rerr = m; return x; }
    static Message ack() { Message x; x.type = RREP_ACK_TYPE; return x; }
};

// Bytes of one message; throws std::invalid_argument where a field does not fit (as
// aodv/packet.py raises ValueError).
std::string encode(const Message& m);
// Parse one UDP payload; false (and `why`) where aodv/packet.py raises MalformedPacket.
bool decode(const uint8_t* data, size_t n, Message& out, std::string* why = nullptr);

// RFC 6.9 HELLO: a RREP about its own sender (Destination = Originator = IP source), 0 hops.
bool is_hello(const Message& m, Addr src);

}  // namespace aodv
