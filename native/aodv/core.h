// The AODV protocol core (RFC 3561) in C++17: the compiled twin of aodv/core.py.
//
// Sans-IO like its reference: events with `now` (seconds of any monotonic clock) in, a
// list of actions out, and next_deadline() after every event. The theory of operation is
// at the top of core.cc; the differential test (tests/unit/test_aodv_differential.py)
// holds this core equal to the Python one, action for action.
#pragma once

#include <cstdint>
#include <deque>
#include <map>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "ordered_map.h"
#include "packet.h"
#include "params.h"

namespace aodv {

// Decision (RREP IP TTL): 64, so a RREP is never taken for a HELLO (aodv/actions.py).
constexpr int UNICAST_TTL = 64;
// RFC 6.11 / 6.9: the limited broadcast with IP TTL 1.
constexpr int LOCAL_TTL = 1;

// -- actions (aodv/actions.py) ---------------------------------------------------------
enum class Act { Unicast, Broadcast, Install, Delete, Release, Drop, Done };

struct Action {
    Act kind = Act::Unicast;
    Message msg;                       // Unicast, Broadcast
    Addr addr = 0;                     // Unicast: dst; the others: dest
    int ttl = 0;                       // Unicast, Broadcast
    Addr next_hop = 0;                 // Install
    int hops = 0;                      // Install
    std::vector<std::string> packets;  // Release, Drop (opaque bytes)
    bool ok = false;                   // Done
    double latency = 0, round_latency = 0;
    bool repair = false;

    bool is_send() const { return kind == Act::Unicast || kind == Act::Broadcast; }
};

// -- sequence numbers (aodv/seqnum.py, RFC 6.1: signed 32-bit comparison) -----------------
namespace seqnum {
inline int64_t diff(uint32_t a, uint32_t b) { return int64_t(int32_t(uint32_t(a - b))); }
inline bool newer(uint32_t a, uint32_t b) { return diff(a, b) > 0; }
inline bool at_least(uint32_t a, uint32_t b) { return diff(a, b) >= 0; }
inline uint32_t increment(uint32_t a) { return a + 1; }
inline uint32_t newest(uint32_t a, uint32_t b) { return at_least(a, b) ? a : b; }
}  // namespace seqnum

// -- the routing table (aodv/routes.py) --------------------------------------------------
struct Route {
    Addr dest = 0;
    Addr next_hop = 0;
    int hops = 0;
    uint32_t seq = 0;
    bool valid_seq = false;
    double lifetime = 0;
    bool valid = true;
    std::vector<Addr> precursors;  // a set: order never matters
    double active_until = 0;

    void add_precursor(Addr a);
};

class RoutingTable {
  public:
    using Map = OrderedMap<Addr, Route>;
    Route* get(Addr d);
    Route* peek(Addr d) { return routes_.find(d); }
    Route* valid(Addr d);
    Route* add(Route r);
    void remove(Addr d);
    std::vector<Route*> snapshot();  // Python `for r in table`: all entries may change
    const Map& peek_all() const { return routes_; }
    size_t size() const { return routes_.size(); }
    std::vector<Route*> via(Addr next_hop);
    // false when every entry may have changed (Python None); else the touched destinations
    // in the table, in table order, and those no longer in it.
    bool take_touched(std::vector<Addr>& present, std::vector<Addr>& absent);
    bool next_deadline(double& t) const;
    template <class Keep>
    size_t shrink(size_t limit, double now, const Keep& keep);

  private:
    void touch(Addr d) {
        if (!all_ && touched_set_.insert(d).second) touched_.push_back(d);
    }
    Map routes_;
    bool all_ = true;  // the Python table starts with _touched None
    std::vector<Addr> touched_;
    std::unordered_set<Addr> touched_set_;
};

// -- neighbours and the blacklist (aodv/neighbors.py) ------------------------------------
struct Neighbor {
    Addr addr = 0;
    bool has_hello = false;  // Python: last_hello is not None
    double last_hello = 0;
    double last_heard = 0;
    double timeout = 0;
};

class Neighbors {
  public:
    explicit Neighbors(long long limit) : limit_(limit) {}
    Neighbor& heard(Addr a, double now);
    void hello(Addr a, double now, double timeout);
    const Neighbor* get(Addr a) const { return n_.find(a); }
    void forget(Addr a) { n_.erase(a); }
    std::vector<Addr> lost(double now, double delete_period);
    bool next_deadline(double delete_period, double& t) const;
    void blacklist(Addr a, double until) { blacklist_[a] = until; }
    void unblacklist(Addr a) { blacklist_.erase(a); }
    bool blacklisted(Addr a, double now);
    const OrderedMap<Addr, Neighbor>& all() const { return n_; }
    long long evicted = 0;

  private:
    void evict();
    long long limit_;
    OrderedMap<Addr, Neighbor> n_;
    std::unordered_map<Addr, double> blacklist_;
};

// -- duplicate RREQs (aodv/rreq_cache.py) -----------------------------------------------
class RreqCache {
  public:
    explicit RreqCache(long long limit) : limit_(limit) {}
    bool seen(Addr orig, uint32_t id, double now) const;
    void add(Addr orig, uint32_t id, double until, double now);
    void purge(double now);
    size_t size() const { return seen_.size(); }
    long long evicted = 0;

  private:
    static uint64_t key(Addr orig, uint32_t id) { return (uint64_t(orig) << 32) | id; }
    long long limit_;
    OrderedMap<uint64_t, double> seen_;
};

// -- data waiting for a route (aodv/request_queue.py) ------------------------------------
class RequestQueue {
  public:
    explicit RequestQueue(long long limit) : limit_(limit) {}
    // Queue a packet; true (and `overflow`, the oldest) when the queue was full.
    bool push(Addr dest, std::string packet, std::string& overflow);
    std::vector<std::string> pop_all(Addr dest);
    bool contains(Addr dest) const { return q_.count(dest) != 0; }

  private:
    long long limit_;
    std::unordered_map<Addr, std::deque<std::string>> q_;
};

// -- the state shared by the sections (aodv/state.py) ------------------------------------
struct Discovery {
    Addr dest = 0;
    long long ttl = 0;
    double started = 0;
    double deadline = 0;
    double round_started = 0;
    long long retries = 0;
    bool deferred = false;
    bool is_repair = false;  // Python: repair_hops is not None
    int repair_hops = 0;
};

class RateLimit {
  public:
    RateLimit(long long limit, double window) : limit_(limit), window_(window) {}
    bool allow(double now);
    double next_free(double now);

  private:
    void trim(double now);
    long long limit_;
    double window_;
    std::deque<double> times_;
};

class AodvCore {
  public:
    AodvCore(Addr addr, const Params& params, double now, bool rebooted = false,
             uint32_t seq = 0, uint32_t rreq_id = 0);

    // == events (aodv/core.py) ==
    std::vector<Action> on_control(double now, Addr src, int ttl, const Message& msg);
    std::vector<Action> on_no_route(double now, Addr src, Addr dst, std::string packet);
    std::vector<Action> on_route_used(double now, Addr addr);
    std::vector<Action> on_routes_used(double now, const std::vector<Addr>& addrs);
    std::vector<Action> on_link_lost(double now, Addr neighbor);
    std::vector<Action> on_timer(double now);
    double next_deadline() const;

    // == inspection ==
    Addr addr;
    Params p;
    uint32_t seq;
    uint32_t rreq_id;
    RoutingTable table;
    RreqCache rreq_cache;
    Neighbors neighbors;
    RequestQueue queue;
    OrderedMap<Addr, Discovery> discoveries;
    std::unordered_map<Addr, double> pending_acks;  // RFC 6.8
    std::unordered_map<Addr, double> bidirectional;
    double next_hello;
    std::map<std::string, long long> dropped;  // by reason, as the Python Counter
    bool rebooting;                            // Python: reboot_until is not None
    double reboot_until;
    OrderedMap<Addr, std::pair<Addr, int>> installed;  // the kernel's copy (DataPath)

  private:
    using Out = std::vector<Action>;
    std::vector<Action> finish(double now, Out& out);

    // state.py
    void touch_prev_hop(double now, Addr src);
    static void refresh(Route& r, double until);
    void invalidate(Route& r, double now);
    void broadcast(double now, const Message& m, int ttl, Out& out);

    // discovery.py (RFC 6.3-6.5)
    void buffer(Addr dst, std::string packet, Out& out);
    void originate(double now, Addr dst, std::string packet, Out& out);
    void keep_invalid_entry(double now, Addr dst);
    void send_rreq(double now, Discovery& d, Out& out);
    void discovery_timeout(double now, Discovery& d, Out& out);
    // The discovery of `dest` ended: its buffered packets released (ok) or dropped, then
    // its DiscoveryDone (aodv.discovery: both leave in this order).
    void end_discovery(double now, Addr dest, double started, double round_started, bool ok,
                       bool repair, Out& out);
    struct Repaired {
        Discovery d;
        Route* r;
    };
    std::vector<Repaired> complete(double now, Out& out);
    void on_rreq(double now, Addr src, int ttl, const Rreq& m, Out& out);
    Route* update_reverse_route(double now, Addr src, const Rreq& m, int hops);

    // replies.py (RFC 6.6-6.8)
    void as_destination(double now, const Rreq& m, Route& rev, Out& out);
    void as_intermediate(double now, const Rreq& m, Route& rev, Route& fwd, Out& out);
    void send_rrep(double now, Rrep rrep, Addr next_hop, Out& out);
    void on_rrep(double now, Addr src, const Rrep& m, Out& out);
    void rrep_body(double now, Addr src, const Rrep& m, Out& out);
    double peer_lifetime(uint32_t lifetime_ms);
    void on_ack(double now, Addr src);
    void expire_acks(double now);

    // hello.py (RFC 6.9-6.10)
    void on_hello(double now, Addr src, const Rrep& m);
    double peer_hello_interval_ms(uint32_t interval_ms);
    void maybe_send_hello(double now, Out& out);

    // maintenance.py (RFC 6.11-6.12)
    void link_break(double now, Addr nbr, Out& out);
    void forward_without_route(double now, Addr dst, std::string packet, Out& out);
    void on_rerr(double now, Addr src, const Rerr& m, Out& out);
    void send_rerr(double now, const std::vector<Route*>& routes, Out& out, bool fallback,
                   bool no_delete = false);
    void start_repair(double now, Route& r, Out& out);
    void repaired(double now, const Discovery& d, Route& r, Out& out);
    void repair_failed(double now, Addr dest, Out& out);
    void expire_routes(double now);

    // datapath.py
    void used(double now, Addr a);
    std::vector<Action> sync();

    RateLimit rreq_limit_, fwd_limit_, rerr_limit_;
};

}  // namespace aodv
