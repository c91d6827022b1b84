// Flooding over UDP broadcast (node/flood.py): a new flood is delivered and, while its TTL
// allows and the mode says so (self-pruning by default, or blind), relayed once; floods seen
// before (by origin and sequence number, a window of 256 below the highest per origin) and
// our own are dropped. Never blocks on send: a full buffer drops the datagram.
#pragma once

#include <cstdint>
#include <map>
#include <mutex>
#include <set>
#include <string>
#include <vector>

#include "stats.h"
#include "wire.h"

namespace tb {

class DuplicateCache {
public:
    bool seen(int origin, uint32_t seq);  // true if seen before; records it otherwise

private:
    std::map<int, int64_t> high_;
    std::map<int, std::set<int64_t>> recent_;
};

class Flooder {
public:
    Flooder(int me, int port, std::string iface, std::string mode, double hold_s);
    ~Flooder();
    Flooder(const Flooder&) = delete;
    Flooder& operator=(const Flooder&) = delete;
    bool open(std::string& err);
    int fileno() const { return fd_; }
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
    std::string iface_, mode_;
    double hold_;
    uint8_t ttl_ = 16;
    int fd_ = -1;
    uint32_t seq_ = 0;  // the timer's alone
    std::mutex cache_lock_;  // guards cache_ and heard_ (the inbox relays, the timer originates)
    DuplicateCache cache_;
    std::map<int, double> heard_;
    std::mutex counts_lock_;  // guards counts_
    Counter counts_;
    std::vector<uint8_t> recv_buf_ = std::vector<uint8_t>(65535);  // the inbox thread's
};

}  // namespace tb
