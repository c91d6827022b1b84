// What robots say to each other (node/wire.py; docs/robot-contract.md): UDP floods with a
// 16-byte header and a per-copy part, map payloads of zlib'd 2-bit ternary cells, and the
// goal and re-plan messages as JSON. Every decoder returns false with a reason on malformed
// input; callers count and drop it.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "robot_consts.h"

namespace tb {

using gen::KIND_BEACON;
using gen::KIND_MAP;
using gen::FLOOD_FIXED;  // header + sender (2) + neighbour count (1)

struct FloodHeader {
    uint8_t kind = 0, ttl = 0;
    uint16_t origin = 0;
    uint32_t seq = 0, step = 0;
    uint16_t sender = 0;
    std::vector<uint16_t> neighbours;
    size_t payload_at = 0;  // offset of the payload in the datagram
};

std::string pack_flood(const FloodHeader& h, const std::string& payload);
// (ttl, origin, seq, sender) and the neighbours; false when it is not a robot flood.
bool unpack_flood(const uint8_t* d, size_t n, FloodHeader& h, std::string& err);
// The same flood as `sender` retransmits it: TTL, sender and neighbours replaced.
std::string relayed(const uint8_t* d, size_t n, const FloodHeader& h, uint8_t ttl,
                    uint16_t sender, const std::vector<uint16_t>& neighbours);

struct Ternary {  // a window of cells (UNKNOWN 0, FREE 1, OCC 2), row-major
    int h = 0, w = 0;
    std::vector<uint8_t> cells;
};

// node.grid.encode_ternary + wire.pack_map: the known cells' box of `t`, placed at
// (r_off, c_off), with the robot's position.
std::string pack_map(double x, double y, const Ternary& t, int r_off, int c_off);
struct MapMsg {
    double x = 0, y = 0;
    int r0 = 0, c0 = 0;
    Ternary cells;
};
bool unpack_map(const uint8_t* d, size_t n, int rows, int cols, MapMsg& out, std::string& err);
bool decode_ternary(int h, int w, const uint8_t* d, size_t n, Ternary& out, std::string& err);
bool unpack_beacon(const uint8_t* d, size_t n, double& x, double& y, std::string& err);
std::string pack_beacon(double x, double y);

// Goals and re-plan requests. `n` 0: none (older senders).
enum class MsgKind { goal, replan };
const char* msg_kind_name(MsgKind k);  // "goal", "replan": the message's "k"

struct GoalMsg {
    MsgKind k = MsgKind::goal;
    int from = 0;
    int64_t step = 0;
    double gx = 0, gy = 0;
    double cost = 0;
    bool fallback = false;
    int64_t n = 0;
};
std::string goal_msg(int sender, int64_t step, double gx, double gy, double cost, bool fallback,
                     int64_t n);
std::string replan_msg(int sender, int64_t step, double gx, double gy, int64_t n);
bool parse_msg(const std::string& data, int n_robots, GoalMsg& out, std::string& err);

}  // namespace tb
