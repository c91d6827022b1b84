// Flooding over UDP broadcast (node/flood.py): a new flood is delivered and, while its TTL
// allows and the mode says so (self-pruning by default, or blind), relayed once; floods seen
// before (by origin and sequence number, a window of 256 below the highest per origin) and
// our own are dropped, and so is one whose sequence number is not believed (more than
// SEQ_WINDOW from the highest believed, compared with wrap-around; counted as forged and
// malformed). Never blocks on send: a full buffer drops the datagram.
#pragma once

#include <cstdint>
#include <map>
#include <mutex>
#include <set>
#include <string>
#include <vector>

#include "fd.h"
#include "robot_consts.h"
#include "stats.h"
#include "wire.h"

namespace tb {

// node.flood.SEQ_WINDOW: how far from the highest sequence number believed from an origin (0
// before any) another is believed.
using gen::SEQ_WINDOW;

// a - b as a signed 32-bit number (RFC 3561, 6.1): > 0 when a is the newer.
inline int64_t seq_diff(uint32_t a, uint32_t b) { return static_cast<int32_t>(a - b); }

// node.flood.DuplicateCache: per origin, the highest sequence number believed and those seen
// within 256 below it.
class DuplicateCache {
public:
    enum Verdict { NEW, DUPLICATE, FORGED };
    // NEW (recorded), DUPLICATE (seen, or older than the remembered ones) or FORGED (more
    // than SEQ_WINDOW from the highest believed: nothing recorded).
    Verdict check(int origin, uint32_t seq);
    bool seen(int origin, uint32_t seq) { return check(origin, seq) != NEW; }

private:
    std::map<int, uint32_t> high_;
    std::map<int, std::set<uint32_t>> recent_;
};

// tb-robot --decode floodseq (selftest.cc): lines "origin seq" on `in`, one verdict a line
// out (new, duplicate, forged), from one DuplicateCache, as node.flood's.
int flood_seq_selftest(const std::string& in);

class Flooder {
public:
    // `mode`: "blind" relays every new flood, anything else prunes (--flood, checked there).
    Flooder(int me, int port, std::string iface, const std::string& mode, double hold_s);
    Flooder(const Flooder&) = delete;
    Flooder& operator=(const Flooder&) = delete;
    bool open(std::string& err);
    int fileno() const { return fd_.get(); }
    uint32_t originate(uint8_t kind, uint32_t step, const std::string& payload);
    // Drains the socket: the new floods (wire form), relayed on the way.
    std::vector<std::string> receive_raw();
    double count(const std::string& key);
    std::string counts_json();
    MapStats stats;

private:
    std::vector<uint16_t> neighbours(double now);  // cache lock held
    bool must_relay(int sender, int origin, const std::vector<uint16_t>& covered, double now);
    bool send(const std::string& data);
    void note(const std::string& key);

    int me_, port_;
    std::string iface_;
    bool blind_;  // --flood blind, not self-pruning
    double hold_;
    uint8_t ttl_ = gen::FLOOD_TTL;
    Fd fd_;
    uint32_t seq_ = 0;  // the timer's alone
    std::mutex cache_lock_;  // guards cache_ and heard_ (the inbox relays, the timer originates)
    DuplicateCache cache_;
    std::map<int, double> heard_;
    std::mutex counts_lock_;  // guards counts_
    Counter counts_;
    std::vector<uint8_t> recv_buf_ = std::vector<uint8_t>(65535);  // the inbox thread's
};

}  // namespace tb
