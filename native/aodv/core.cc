// The AODV protocol core (RFC 3561) in C++17, the compiled twin of aodv/core.py.
//
// Theory of operation
// -------------------
// `AodvCore` is the whole protocol of one node and nothing else: no socket, no clock, no
// thread. The daemon (or the driver program, tb-aodv-core) feeds it events, each with `now`
// (seconds of any monotonic clock), and carries out the actions it returns, in order:
//
//     events                                   actions
//     on_control(now, src, ttl, msg)           Unicast(msg, dst, ttl), Broadcast(msg, ttl)
//     on_no_route(now, src, dst, packet)       Install(dest, next_hop, hops), Delete(dest)
//     on_route_used / on_routes_used(now, ..)  Release(dest, packets), Drop(dest, packets)
//     on_link_lost(now, neighbor)              Done(dest, ok, latency, round_latency, repair)
//     on_timer(now)
//
// and after every event next_deadline() says when on_timer must run next.
//
// The Python core (aodv/core.py and the modules it composes) is the reference: this file
// does what it does, decision for decision, in the same order, so that both give the same
// actions in the same order, the same deadlines (bit for bit: every double is computed
// with the Python expression's operations in its order) and the same `dropped` counters.
// tests/unit/test_aodv_differential.py holds the two equal. The sections below are named
// after the Python modules and the RFC sections they implement:
//
//     state        what several sections do to the shared state (aodv/state.py)
//     discovery    RREQ origination, ring search, buffering, RREQ processing (6.3-6.5)
//     replies      RREP generation and processing, RREP-ACK (6.6-6.8)
//     hello        HELLOs and neighbour liveness (6.9-6.10)
//     maintenance  RERR, local repair, route expiry (6.11-6.12)
//     datapath     route use (6.2) and the kernel's copy of the valid routes
//
// Where the Python core leaves an order to a Python dict (the routing table, the kernel's
// copy, the neighbours, the discoveries, the RREQ cache), this core keeps insertion order
// too (ordered_map.h); where it uses a set (precursors), no output depends on the order.
// The Python table remembers which entries an event touched and the kernel diff looks at
// those only; this core tracks the same touches, so an entry changed behind the table's
// back would be missed here exactly as there. The "Decision:" notes of the Python modules
// are summarised at each branch; the full text is in the Python and docs/aodv.md.
#include "core.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace aodv {

namespace {
double pymax(double a, double b) { return b > a ? b : a; }
}  // namespace

// == containers ==========================================================================
void Route::add_precursor(Addr a) {
    if (std::find(precursors.begin(), precursors.end(), a) == precursors.end())
        precursors.push_back(a);
}

Route* RoutingTable::get(Addr d) {
    touch(d);
    return routes_.find(d);
}

Route* RoutingTable::valid(Addr d) {
    touch(d);
    Route* r = routes_.find(d);
    return r != nullptr && r->valid ? r : nullptr;
}

Route* RoutingTable::add(Route r) {
    touch(r.dest);
    Addr d = r.dest;
    return &routes_.assign(d, std::move(r));
}

void RoutingTable::remove(Addr d) {
    touch(d);
    routes_.erase(d);
}

std::vector<Route*> RoutingTable::snapshot() {
    all_ = true;
    std::vector<Route*> out;
    out.reserve(routes_.size());
    for (auto& e : routes_) out.push_back(&e.value);
    return out;
}

std::vector<Route*> RoutingTable::via(Addr next_hop) {
    std::vector<Route*> out;
    for (auto& e : routes_)
        if (e.value.valid && e.value.next_hop == next_hop) out.push_back(&e.value);
    for (Route* r : out) touch(r->dest);
    return out;
}

bool RoutingTable::take_touched(std::vector<Addr>& present, std::vector<Addr>& absent) {
    present.clear();
    absent.clear();
    bool all = all_;
    all_ = false;
    std::vector<Addr> touched;
    touched.swap(touched_);
    touched_set_.clear();
    if (all) return false;
    std::vector<std::pair<uint64_t, Addr>> in;
    for (Addr d : touched) {
        uint64_t st = routes_.stamp(d);
        if (st == UINT64_MAX)
            absent.push_back(d);
        else
            in.emplace_back(st, d);
    }
    std::sort(in.begin(), in.end());
    for (auto& x : in) present.push_back(x.second);
    return true;
}

bool RoutingTable::next_deadline(double& t) const {
    // The soonest lifetime of any entry (the Python heap's answer, without the heap).
    bool any = false;
    for (const auto& e : routes_) {
        if (!any || e.value.lifetime < t) t = e.value.lifetime;
        any = true;
    }
    return any;
}

template <class Keep>
size_t RoutingTable::shrink(size_t limit, double now, const Keep& keep) {
    // aodv/routes.py `shrink`: invalid entries first, then valid ones no data used lately,
    // then the rest, each soonest-to-expire first (a stable sort: ties in table order);
    // destinations being discovered stay.
    if (routes_.size() <= limit) return 0;
    size_t target = size_t(double(limit) * 0.9);
    std::vector<Route*> victims;
    for (auto& e : routes_)
        if (!keep.contains(e.key)) victims.push_back(&e.value);
    auto cls = [now](const Route* r) {
        return r->valid && r->active_until > now ? 2 : r->valid ? 1 : 0;
    };
    std::stable_sort(victims.begin(), victims.end(), [&](const Route* a, const Route* b) {
        int ca = cls(a), cb = cls(b);
        if (ca != cb) return ca < cb;
        return a->lifetime < b->lifetime;
    });
    size_t n = std::min(victims.size(), routes_.size() - target);
    std::vector<Addr> gone;
    for (size_t i = 0; i < n; ++i) gone.push_back(victims[i]->dest);
    for (Addr d : gone) {
        touch(d);
        routes_.erase(d);
    }
    return n;
}

Neighbor& Neighbors::heard(Addr a, double now) {
    Neighbor* n = n_.find(a);
    if (n == nullptr) {
        if ((long long)n_.size() >= limit_) evict();
        Neighbor fresh;
        fresh.addr = a;
        n = &n_.assign(a, fresh);
    }
    n->last_heard = now;
    return *n;
}

void Neighbors::evict() {
    // Decision (aodv/neighbors.py): past the bound the neighbours heard least recently are
    // forgotten, down to 90% of it (a stable sort: ties in insertion order).
    std::vector<std::pair<double, Addr>> by_age;
    for (const auto& e : n_) by_age.emplace_back(e.value.last_heard, e.key);
    std::stable_sort(by_age.begin(), by_age.end(),
                     [](const auto& x, const auto& y) { return x.first < y.first; });
    long long keep = (long long)(double(limit_) * 0.9);
    long long drop = (long long)by_age.size() - keep;
    for (long long i = 0; i < drop && i < (long long)by_age.size(); ++i) {
        n_.erase(by_age[size_t(i)].second);
        ++evicted;
    }
    if ((long long)blacklist_.size() >= limit_) blacklist_.clear();
}

void Neighbors::hello(Addr a, double now, double timeout) {
    Neighbor& n = heard(a, now);
    n.has_hello = true;
    n.last_hello = now;
    n.timeout = timeout;
}

namespace {
// RFC 6.10's condition when the neighbour's allowed silence ends: a HELLO came from it
// within DELETE_PERIOD before that moment (aodv/neighbors.py `_monitored_at_break`).
bool monitored_at_break(const Neighbor& n, double dp) {
    return n.has_hello && n.last_hello >= n.last_heard + n.timeout - dp;
}
}  // namespace

std::vector<Addr> Neighbors::lost(double now, double dp) {
    std::vector<Addr> out;
    for (auto it = n_.begin(); it != n_.end();) {
        const Neighbor& n = it->value;
        if (monitored_at_break(n, dp)) {
            if (now >= n.last_heard + n.timeout) {
                out.push_back(n.addr);
                it = n_.erase(it);
                continue;
            }
        } else if (now >= n.last_heard + dp) {  // at next_deadline's instant
            it = n_.erase(it);
            continue;
        }
        ++it;
    }
    return out;
}

bool Neighbors::next_deadline(double dp, double& t) const {
    bool any = false;
    for (const auto& e : n_) {
        const Neighbor& n = e.value;
        if (!n.has_hello) continue;
        double c = monitored_at_break(n, dp) ? n.last_heard + n.timeout : n.last_heard + dp;
        if (!any || c < t) t = c;
        any = true;
    }
    return any;
}

bool Neighbors::blacklisted(Addr a, double now) {
    auto it = blacklist_.find(a);
    if (it == blacklist_.end()) return false;
    if (it->second <= now) {
        blacklist_.erase(it);
        return false;
    }
    return true;
}

bool RreqCache::seen(Addr orig, uint32_t id, double now) const {
    const double* e = seen_.find(key(orig, id));
    return e != nullptr && *e > now;
}

void RreqCache::add(Addr orig, uint32_t id, double until, double now) {
    uint64_t k = key(orig, id);
    seen_.erase(k);  // re-inserted at the end: insertion order = age
    seen_.assign(k, until);
    if ((long long)seen_.size() > limit_) {
        purge(now);
        while ((long long)seen_.size() > limit_) {
            seen_.erase(seen_.begin());
            ++evicted;
        }
    }
}

void RreqCache::purge(double now) {
    for (auto it = seen_.begin(); it != seen_.end();) {
        if (it->value <= now)
            it = seen_.erase(it);
        else
            ++it;
    }
}

bool RequestQueue::push(Addr dest, std::string packet, std::string& overflow) {
    auto& q = q_[dest];
    q.push_back(std::move(packet));
    if ((long long)q.size() > limit_) {
        overflow = std::move(q.front());
        q.pop_front();
        return true;
    }
    return false;
}

std::vector<std::string> RequestQueue::pop_all(Addr dest) {
    std::vector<std::string> out;
    auto it = q_.find(dest);
    if (it == q_.end()) return out;
    for (auto& p : it->second) out.push_back(std::move(p));
    q_.erase(it);
    return out;
}

void RateLimit::trim(double now) {
    // The same sum as next_free's deadline (aodv/state.py RateLimit._trim).
    while (!times_.empty() && times_.front() + window_ <= now) times_.pop_front();
}

bool RateLimit::allow(double now) {
    trim(now);
    if ((long long)times_.size() >= limit_) return false;
    times_.push_back(now);
    return true;
}

double RateLimit::next_free(double now) {
    trim(now);
    return (long long)times_.size() >= limit_ ? times_.front() + window_ : now;
}

// == the core ============================================================================
AodvCore::AodvCore(Addr addr_, const Params& params, double now, bool rebooted,
                   uint32_t seq_, uint32_t rreq_id_)
    : addr(addr_),
      p(params),
      seq(seq_),
      rreq_id(rreq_id_),
      rreq_cache(params.rreq_cache_limit),
      neighbors(params.neighbor_limit),
      queue(params.queue_len),
      next_hello(now + params.hello_interval),
      // RFC 6.13: "...after rebooting, a node MUST wait for DELETE_PERIOD before
      // transmitting any route discovery messages." Decision: the daemon says whether this
      // start is a reboot.
      rebooting(rebooted),
      reboot_until(rebooted ? now + params.delete_period : 0.0),
      rreq_limit_(params.rreq_ratelimit, params.rate_window),
      fwd_limit_(params.rreq_forward_ratelimit, params.rate_window),
      rerr_limit_(params.rerr_ratelimit, params.rate_window) {}

// == public events (aodv/core.py) ==========================================================
std::vector<Action> AodvCore::on_control(double now, Addr src, int ttl, const Message& msg) {
    Out out;
    if (src == addr) return out;
    // RFC 6.10: any packet from a neighbour shows the link is alive.
    neighbors.heard(src, now);
    // Decision: a RREQ or RREP of NET_DIAMETER hops or more describes no path this network
    // can have, and one more hop would not fit the one-byte field: drop it.
    if ((msg.type == RREQ_TYPE && msg.rreq.hop_count >= p.net_diameter) ||
        (msg.type == RREP_TYPE && msg.rrep.hop_count >= p.net_diameter)) {
        dropped["hop_count"] += 1;
        return finish(now, out);
    }
    switch (msg.type) {
        case RREQ_TYPE:
            on_rreq(now, src, ttl, msg.rreq, out);  // RFC 6.5
            break;
        case RREP_TYPE:
            if (is_hello(msg, src))
                on_hello(now, src, msg.rrep);  // RFC 6.9
            else
                on_rrep(now, src, msg.rrep, out);  // RFC 6.7
            break;
        case RERR_TYPE:
            on_rerr(now, src, msg.rerr, out);  // RFC 6.11 (iii)
            break;
        case RREP_ACK_TYPE:
            on_ack(now, src);  // RFC 6.8
            break;
    }
    return finish(now, out);
}

std::vector<Action> AodvCore::on_no_route(double now, Addr src, Addr dst, std::string packet) {
    Out out;
    if (table.valid(dst) != nullptr) {
        // A valid route the kernel has lost: install it again and send the packet on.
        installed.erase(dst);
        Action a;
        a.kind = Act::Release;
        a.addr = dst;
        a.packets.push_back(std::move(packet));
        out.push_back(std::move(a));
    } else if (src == addr) {
        originate(now, dst, std::move(packet), out);  // RFC 6.3
    } else {
        forward_without_route(now, dst, std::move(packet), out);  // RFC 6.11 (ii)
    }
    return finish(now, out);
}

std::vector<Action> AodvCore::on_route_used(double now, Addr a) {
    return on_routes_used(now, std::vector<Addr>{a});
}

std::vector<Action> AodvCore::on_routes_used(double now, const std::vector<Addr>& addrs) {
    for (Addr a : addrs) used(now, a);
    Out out;
    return finish(now, out);
}

std::vector<Action> AodvCore::on_link_lost(double now, Addr neighbor) {
    Out out;
    neighbors.forget(neighbor);
    link_break(now, neighbor, out);
    return finish(now, out);
}

std::vector<Action> AodvCore::on_timer(double now) {
    Out out;
    if (rebooting && now >= reboot_until) rebooting = false;
    // RFC 6.10 / 6.11 (i): silent monitored neighbours are lost links.
    for (Addr n : neighbors.lost(now, p.delete_period)) link_break(now, n, out);
    expire_routes(now);
    rreq_cache.purge(now);
    expire_acks(now);  // RFC 6.8
    std::vector<Addr> keys;
    for (const auto& e : discoveries) keys.push_back(e.key);
    for (Addr k : keys) {
        Discovery* d = discoveries.find(k);
        if (d == nullptr || !(d->deadline <= now)) continue;
        if (d->is_repair && !d->deferred)
            repair_failed(now, k, out);  // RFC 6.12
        else
            discovery_timeout(now, *d, out);  // RFC 6.3 / 6.4
    }
    if (now >= next_hello) maybe_send_hello(now, out);  // RFC 6.9
    return finish(now, out);
}

double AodvCore::next_deadline() const {
    double t = next_hello, c = 0;
    if (table.next_deadline(c) && c < t) t = c;
    if (neighbors.next_deadline(p.delete_period, c) && c < t) t = c;
    if (rebooting && reboot_until < t) t = reboot_until;
    for (const auto& e : discoveries)
        if (e.value.deadline < t) t = e.value.deadline;
    for (const auto& [a, dl] : pending_acks)
        if (dl < t) t = dl;
    return t;
}

// == after every event ====================================================================
std::vector<Action> AodvCore::finish(double now, Out& out) {
    if (!discoveries.empty()) {
        // Discoveries that now have a route release their packets; a local repair that
        // found a longer route is reported by route maintenance (RFC 6.12).
        for (auto& x : complete(now, out)) repaired(now, x.d, *x.r, out);
    }
    if ((long long)table.size() > p.route_table_limit) {
        size_t gone = table.shrink(size_t(p.route_table_limit), now, discoveries);
        dropped["route_evicted"] += (long long)gone;
    }
    std::vector<Action> routes = sync();
    if (out.empty()) return routes;
    // Decision: control messages leave before the route changes of the same event (they
    // are what the next node waits for, and never need those routes); RREP-ACKs (RFC 6.8)
    // go last, after the releases and DiscoveryDone: nobody's discovery waits for them.
    std::vector<Action> res;
    res.reserve(out.size() + routes.size());
    for (auto& a : out)
        if (a.is_send() && a.msg.type != RREP_ACK_TYPE) res.push_back(std::move(a));
    for (auto& a : routes) res.push_back(std::move(a));
    for (auto& a : out)
        if (!a.is_send()) res.push_back(std::move(a));
    for (auto& a : out)
        if (a.is_send() && a.msg.type == RREP_ACK_TYPE) res.push_back(std::move(a));
    return res;
}

// == state (aodv/state.py) =================================================================
void AodvCore::touch_prev_hop(double now, Addr src) {
    // A route to a neighbour just heard, without a valid sequence number.
    Route* r = table.get(src);
    double until = now + p.active_route_timeout;
    if (r == nullptr) {
        Route n;
        n.dest = src;
        n.next_hop = src;
        n.hops = 1;
        n.seq = 0;
        n.valid_seq = false;
        n.lifetime = until;
        table.add(std::move(n));
    } else if (!r->valid || r->next_hop != src) {
        r->valid = true;
        r->next_hop = src;
        r->hops = 1;
        r->lifetime = until;
    } else {
        r->lifetime = pymax(r->lifetime, until);
    }
}

void AodvCore::refresh(Route& r, double until) {
    r.lifetime = pymax(r.lifetime, until);
    r.active_until = pymax(r.active_until, until);
}

void AodvCore::invalidate(Route& r, double now) {
    // RFC 6.11: "2. The entry is invalidated by marking the route entry as invalid
    // 3. The Lifetime field is updated to current time plus DELETE_PERIOD."
    r.valid = false;
    r.lifetime = now + p.delete_period;
}

void AodvCore::broadcast(double now, const Message& m, int ttl, Out& out) {
    // RFC 6.9: a broadcast of any kind postpones the next HELLO.
    Action a;
    a.kind = Act::Broadcast;
    a.msg = m;
    a.ttl = ttl;
    out.push_back(std::move(a));
    next_hello = now + p.hello_interval;
}

// == discovery (aodv/discovery.py, RFC 6.3-6.5) ===========================================
void AodvCore::buffer(Addr dst, std::string packet, Out& out) {
    // RFC 6.3: buffered FIFO; a full queue drops its oldest.
    std::string overflow;
    if (queue.push(dst, std::move(packet), overflow)) {
        Action a;
        a.kind = Act::Drop;
        a.addr = dst;
        a.packets.push_back(std::move(overflow));
        out.push_back(std::move(a));
    }
}

void AodvCore::originate(double now, Addr dst, std::string packet, Out& out) {
    buffer(dst, std::move(packet), out);
    keep_invalid_entry(now, dst);
    if (discoveries.contains(dst)) return;
    // RFC 6.4: TTL_START, or the old hop count plus TTL_INCREMENT when an (invalid) entry
    // knows the old distance.
    Route* old = table.get(dst);
    long long ttl = old == nullptr ? p.ttl_start : old->hops + p.ttl_increment;
    if (ttl > p.ttl_threshold) ttl = p.net_diameter;
    Discovery d;
    d.dest = dst;
    d.ttl = ttl;
    d.started = now;
    Discovery& dd = discoveries.assign(dst, d);
    send_rreq(now, dd, out);
}

void AodvCore::keep_invalid_entry(double now, Addr dst) {
    // RFC 6.3 / 6.11: data for a destination whose entry is invalid keeps the entry (and
    // its sequence number) for another DELETE_PERIOD.
    Route* r = table.get(dst);
    if (r != nullptr && !r->valid) r->lifetime = pymax(r->lifetime, now + p.delete_period);
}

void AodvCore::send_rreq(double now, Discovery& d, Out& out) {
    // RFC 6.13: after rebooting, no route discovery for DELETE_PERIOD; the data waits.
    if (rebooting && now < reboot_until) {
        d.deferred = true;
        d.deadline = reboot_until;
        return;
    }
    // RFC 6.3: RREQ_RATELIMIT. Decision: a RREQ over the limit is delayed, not dropped.
    if (!rreq_limit_.allow(now)) {
        d.deferred = true;
        d.deadline = rreq_limit_.next_free(now);
        return;
    }
    d.deferred = false;
    keep_invalid_entry(now, d.dest);
    // RFC 6.1: increment the own sequence number before a route discovery; RFC 6.3: the
    // RREQ ID is incremented by one.
    seq = seqnum::increment(seq);
    rreq_id = seqnum::increment(rreq_id);
    // RFC 6.3: the last known destination sequence number, else the U flag.
    Route* old = table.get(d.dest);
    bool known = old != nullptr && old->valid_seq;
    Rreq r;
    r.rreq_id = rreq_id;
    r.dest = d.dest;
    r.dest_seq = known ? old->seq : 0;
    r.orig = addr;
    r.orig_seq = seq;
    r.hop_count = 0;
    r.gratuitous = p.gratuitous_rrep;
    r.dest_only = p.dest_only;
    r.unknown_seq = !known;
    // RFC 6.3: buffer the own RREQ ID for PATH_DISCOVERY_TIME before broadcasting.
    rreq_cache.add(addr, rreq_id, now + p.path_discovery_time, now);
    broadcast(now, Message::of(r), int(d.ttl), out);
    d.round_started = now;
    // RFC 6.4: RING_TRAVERSAL_TIME during the ring search, then NET_TRAVERSAL_TIME; RFC 6.3:
    // binary exponential backoff, 2^k * NET_TRAVERSAL_TIME for retry k.
    if (d.ttl >= p.net_diameter)
        d.deadline = now + std::ldexp(1.0, int(d.retries)) * p.net_traversal_time;
    else
        d.deadline = now + p.ring_traversal_time(d.ttl);
}

void AodvCore::discovery_timeout(double now, Discovery& d, Out& out) {
    if (d.deferred) {
        send_rreq(now, d, out);
        return;
    }
    if (d.ttl < p.net_diameter) {
        // RFC 6.4: TTL_INCREMENT up to TTL_THRESHOLD, then NET_DIAMETER.
        d.ttl += p.ttl_increment;
        if (d.ttl > p.ttl_threshold) d.ttl = p.net_diameter;
        send_rreq(now, d, out);
        return;
    }
    // RFC 6.3: up to RREQ_RETRIES more at the maximum TTL.
    if (d.retries < p.rreq_retries) {
        d.retries += 1;
        send_rreq(now, d, out);
        return;
    }
    // RFC 6.3: drop the buffered packets, Destination Unreachable to the application.
    Addr dest = d.dest;
    double started = d.started, round_started = d.round_started;
    discoveries.erase(dest);
    end_discovery(now, dest, started, round_started, false, false, out);
}

void AodvCore::end_discovery(double now, Addr dest, double started, double round_started,
                             bool ok, bool repair, Out& out) {
    Action packets;
    packets.kind = ok ? Act::Release : Act::Drop;
    packets.addr = dest;
    packets.packets = queue.pop_all(dest);
    out.push_back(std::move(packets));
    Action done;
    done.kind = Act::Done;
    done.addr = dest;
    done.ok = ok;
    done.latency = now - started;
    done.round_latency = now - round_started;
    done.repair = repair;
    out.push_back(std::move(done));
}

std::vector<AodvCore::Repaired> AodvCore::complete(double now, Out& out) {
    // Release the packets of every discovery that now has a valid route; return the local
    // repairs among them (with their new routes) for route maintenance.
    std::vector<Repaired> rep;
    std::vector<Addr> keys;
    for (const auto& e : discoveries) keys.push_back(e.key);
    for (Addr dest : keys) {
        Route* r = table.valid(dest);
        if (r == nullptr) continue;
        Discovery d = *discoveries.find(dest);
        discoveries.erase(dest);
        end_discovery(now, dest, d.started, d.round_started, true, d.is_repair, out);
        if (d.is_repair) rep.push_back(Repaired{d, r});
    }
    return rep;
}

void AodvCore::on_rreq(double now, Addr src, int ttl, const Rreq& m, Out& out) {
    // RFC 6.8: ignore RREQs from blacklisted neighbours.
    if (neighbors.blacklisted(src, now)) return;
    // RFC 6.5: a route to the previous hop without a valid sequence number.
    touch_prev_hop(now, src);
    if (m.orig == addr) return;
    // RFC 6.5: duplicate (Originator, RREQ ID) within PATH_DISCOVERY_TIME: discard.
    if (rreq_cache.seen(m.orig, m.rreq_id, now)) return;
    rreq_cache.add(m.orig, m.rreq_id, now + p.path_discovery_time, now);
    int hops = m.hop_count + 1;  // RFC 6.5
    Route* rev = update_reverse_route(now, src, m, hops);
    // RFC 6.13: while it waits, a rebooted node learns routes but forwards nothing.
    if (rebooting) return;
    if (m.dest == addr) {
        as_destination(now, m, *rev, out);
        return;
    }
    // RFC 6.6 (ii): answer from an active route with a fresh enough valid number, unless D.
    // Decisions: with U any valid number will do; never answer with a route whose next hop
    // is the node that asked.
    Route* fwd = table.valid(m.dest);
    if (fwd != nullptr && fwd->valid_seq && !m.dest_only &&
        (m.unknown_seq || seqnum::at_least(fwd->seq, m.dest_seq)) && fwd->next_hop != src) {
        as_intermediate(now, m, *rev, *fwd, out);
        return;
    }
    // RFC 6.5: forward only if the IP TTL allows.
    if (ttl <= 1) return;
    // Not in RFC 3561: a flood guard on forwarded RREQs.
    if (!fwd_limit_.allow(now)) {
        dropped["rreq_forward_ratelimit"] += 1;
        return;
    }
    // RFC 6.5: the destination sequence number is the maximum of the RREQ's and ours.
    Route* known = table.get(m.dest);
    uint32_t dest_seq = m.dest_seq;
    bool unknown = m.unknown_seq;
    if (known != nullptr && known->valid_seq) {
        dest_seq = unknown ? known->seq : seqnum::newest(m.dest_seq, known->seq);
        unknown = false;
    }
    Rreq f = m;
    f.dest_seq = dest_seq;
    f.hop_count = hops;
    f.unknown_seq = unknown;
    broadcast(now, Message::of(f), ttl - 1, out);
}

Route* AodvCore::update_reverse_route(double now, Addr src, const Rreq& m, int hops) {
    // RFC 6.5: the reverse route to the originator; MinimalLifetime = now +
    // 2*NET_TRAVERSAL_TIME - 2*HopCount*NODE_TRAVERSAL_TIME. Decision: the next hop changes
    // only on a fresher RREQ, an equally fresh and shorter one, or an unusable entry.
    double minimal = now + 2 * p.net_traversal_time - double(2 * hops) * p.node_traversal_time;
    Route* r = table.get(m.orig);
    if (r == nullptr) {
        Route n;
        n.dest = m.orig;
        n.next_hop = src;
        n.hops = hops;
        n.seq = m.orig_seq;
        n.valid_seq = true;
        n.lifetime = minimal;
        return table.add(std::move(n));
    }
    bool better = !r->valid || !r->valid_seq || seqnum::newer(m.orig_seq, r->seq) ||
                  (m.orig_seq == r->seq && hops < r->hops);
    if (!r->valid_seq || seqnum::newer(m.orig_seq, r->seq)) r->seq = m.orig_seq;
    r->valid_seq = true;
    if (better) {
        r->next_hop = src;
        r->hops = hops;
    }
    r->lifetime = r->valid ? pymax(r->lifetime, minimal) : minimal;
    r->valid = true;
    return r;
}

// == replies (aodv/replies.py, RFC 6.6-6.8) ===============================================
namespace {
// The longest Lifetime taken from a peer's RREP, in units of our MY_ROUTE_TIMEOUT.
constexpr double MAX_LIFETIME_FACTOR = 10;
}  // namespace

void AodvCore::as_destination(double now, const Rreq& m, Route& rev, Out& out) {
    // RFC 6.1: our number becomes max(own, RREQ's) (Decision: covers 6.6.1's increment;
    // with U the RREQ's number is ignored). RFC 6.6.1: hop count 0, MY_ROUTE_TIMEOUT.
    if (!m.unknown_seq) seq = seqnum::newest(seq, m.dest_seq);
    Rrep r;
    r.dest = addr;
    r.dest_seq = seq;
    r.orig = m.orig;
    r.lifetime_ms = uint32_t(p.ms(p.my_route_timeout));
    r.hop_count = 0;
    rev.active_until = pymax(rev.active_until, rev.lifetime);
    send_rrep(now, r, rev.next_hop, out);
}

void AodvCore::as_intermediate(double now, const Rreq& m, Route& rev, Route& fwd, Out& out) {
    // RFC 6.6.2: our number and distance for the destination, the remaining lifetime; the
    // precursors of both routes.
    fwd.add_precursor(rev.next_hop);
    rev.add_precursor(fwd.next_hop);
    fwd.active_until = pymax(fwd.active_until, fwd.lifetime);
    rev.active_until = pymax(rev.active_until, rev.lifetime);
    Rrep r;
    r.dest = m.dest;
    r.dest_seq = fwd.seq;
    r.orig = m.orig;
    r.lifetime_ms = uint32_t(p.ms(fwd.lifetime - now));
    r.hop_count = fwd.hops;
    send_rrep(now, r, rev.next_hop, out);
    // RFC 6.6.3: with G, a gratuitous RREP to the destination too.
    if (m.gratuitous) {
        Rrep g;
        g.dest = m.orig;
        g.dest_seq = m.orig_seq;
        g.orig = m.dest;
        g.lifetime_ms = uint32_t(p.ms(rev.lifetime - now));
        g.hop_count = rev.hops;
        send_rrep(now, g, fwd.next_hop, out);
    }
}

void AodvCore::send_rrep(double now, Rrep rrep, Addr next_hop, Out& out) {
    // RFC 6.7/6.8: the A flag over a link likely unidirectional. Decision: one is until
    // the neighbour showed it hears us (a RREP-ACK or a RREP) within DELETE_PERIOD.
    auto it = bidirectional.find(next_hop);
    if (it == bidirectional.end() || it->second < now - p.delete_period) {
        rrep.ack_required = true;
        pending_acks[next_hop] = now + p.next_hop_wait;
    }
    Action a;
    a.kind = Act::Unicast;
    a.msg = Message::of(rrep);
    a.addr = next_hop;
    a.ttl = UNICAST_TTL;
    out.push_back(std::move(a));
}

void AodvCore::on_rrep(double now, Addr src, const Rrep& m, Out& out) {
    rrep_body(now, src, m, out);
    // RFC 6.8: a RREP with A is acknowledged (finish() puts the RREP-ACK last).
    if (m.ack_required) {
        Action a;
        a.kind = Act::Unicast;
        a.msg = Message::ack();
        a.addr = src;
        a.ttl = UNICAST_TTL;
        out.push_back(std::move(a));
    }
}

void AodvCore::rrep_body(double now, Addr src, const Rrep& m, Out& out) {
    bidirectional[src] = now;
    // RFC 6.7: a route to the previous hop, without a valid sequence number.
    touch_prev_hop(now, src);
    if (m.dest == addr) return;
    int hops = m.hop_count + 1;  // RFC 6.7
    Route* r = table.get(m.dest);
    // RFC 6.7: update only on (i) an invalid number, (ii) a newer one, (iii) the same and
    // the route inactive, (iv) the same and fewer hops.
    if (r == nullptr) {
        Route n;
        n.dest = m.dest;
        n.next_hop = src;
        n.hops = hops;
        n.seq = m.dest_seq;
        n.valid_seq = true;
        n.lifetime = 0.0;
        r = table.add(std::move(n));
    } else if (!(!r->valid_seq || seqnum::newer(m.dest_seq, r->seq) ||
                 (m.dest_seq == r->seq && !r->valid) ||
                 (m.dest_seq == r->seq && hops < r->hops))) {
        return;
    }
    r->valid = true;
    r->valid_seq = true;
    r->next_hop = src;
    r->hops = hops;
    r->lifetime = now + peer_lifetime(m.lifetime_ms);
    r->seq = m.dest_seq;
    r->active_until = r->lifetime;
    if (m.orig == addr || rebooting) return;
    // RFC 6.7: forward towards the originator along the reverse route.
    Route* rev = table.valid(m.orig);
    if (rev == nullptr) return;
    // RFC 6.7: precursors and the reverse route's lifetime. Decision (as ns-3): the
    // symmetric entries are filled too.
    r->add_precursor(rev->next_hop);
    rev->add_precursor(r->next_hop);
    refresh(*rev, now + p.active_route_timeout);
    Route* nh_dst = table.valid(r->next_hop);
    if (nh_dst != nullptr) nh_dst->add_precursor(rev->next_hop);
    Route* nh_src = table.valid(rev->next_hop);
    if (nh_src != nullptr) nh_src->add_precursor(r->next_hop);
    Rrep f;
    f.dest = m.dest;
    f.dest_seq = m.dest_seq;
    f.orig = m.orig;
    f.lifetime_ms = m.lifetime_ms;
    f.hop_count = hops;
    f.prefix_size = m.prefix_size;
    send_rrep(now, f, rev->next_hop, out);
}

double AodvCore::peer_lifetime(uint32_t lifetime_ms) {
    // Decision: a peer's Lifetime is at most MAX_LIFETIME_FACTOR * MY_ROUTE_TIMEOUT.
    double limit = MAX_LIFETIME_FACTOR * p.my_route_timeout;
    double t = p.from_ms(double(lifetime_ms));
    if (t > limit) {
        dropped["lifetime_clamped"] += 1;
        return limit;
    }
    return t;
}

void AodvCore::on_ack(double now, Addr src) {
    // RFC 6.8. Decision: a late RREP-ACK still proves the link: it lifts the blacklisting.
    pending_acks.erase(src);
    bidirectional[src] = now;
    neighbors.unblacklist(src);
}

void AodvCore::expire_acks(double now) {
    // RFC 6.8: no RREP-ACK within NEXT_HOP_WAIT: blacklisted for BLACKLIST_TIMEOUT.
    for (auto it = pending_acks.begin(); it != pending_acks.end();) {
        if (it->second <= now) {
            neighbors.blacklist(it->first, now + p.blacklist_timeout);
            it = pending_acks.erase(it);
        } else {
            ++it;
        }
    }
    // The proofs of bidirectional links are bounded as the neighbour list is.
    if ((long long)bidirectional.size() > p.neighbor_limit) {
        double old = now - p.delete_period;
        for (auto it = bidirectional.begin(); it != bidirectional.end();) {
            if (it->second >= old)
                ++it;
            else
                it = bidirectional.erase(it);
        }
    }
}

// == hello (aodv/hello.py, RFC 6.9-6.10) ===================================================
void AodvCore::on_hello(double now, Addr src, const Rrep& m) {
    // RFC 6.9: an active route to the neighbour, at least ALLOWED_HELLO_LOSS *
    // HELLO_INTERVAL long, with the HELLO's sequence number; the neighbour's own
    // HELLO_INTERVAL from its Hello Interval extension.
    double interval = p.hello_interval;
    if (m.has_hello) interval = p.from_ms(peer_hello_interval_ms(m.hello_interval_ms));
    double timeout = double(p.allowed_hello_loss) * interval;
    neighbors.hello(src, now, timeout);
    Route* r = table.get(src);
    if (r == nullptr || !r->valid) {
        Route n;
        n.dest = src;
        n.next_hop = src;
        n.hops = 1;
        n.seq = m.dest_seq;
        n.valid_seq = true;
        n.lifetime = now + timeout;
        table.add(std::move(n));
        return;
    }
    r->next_hop = src;
    r->hops = 1;
    r->seq = m.dest_seq;
    r->valid_seq = true;
    r->lifetime = pymax(r->lifetime, now + timeout);
}

double AodvCore::peer_hello_interval_ms(uint32_t interval_ms) {
    // Decision: a neighbour's Hello Interval within [ours / 4, ours * 16].
    double own = p.hello_interval_ms;
    double v = double(interval_ms);
    double lo = own / 4, hi = own * 16;
    double clamped = lo > v ? lo : v;  // Python max(v, lo)
    if (hi < clamped) clamped = hi;    // Python min(.., hi)
    if (clamped != v) dropped["hello_interval_clamped"] += 1;
    return clamped;
}

void AodvCore::maybe_send_hello(double now, Out& out) {
    // RFC 6.9: HELLOs only from a node on an active route. Decision: the next check is
    // HELLO_INTERVAL after the last broadcast.
    bool active = false;
    for (const auto& e : table.peek_all()) {
        if (e.value.valid && e.value.active_until > now) {
            active = true;
            break;
        }
    }
    if (active && !rebooting) {
        Rrep h;
        h.dest = addr;
        h.dest_seq = seq;
        h.orig = addr;
        h.lifetime_ms = uint32_t(p.ms(p.neighbor_timeout));
        h.hop_count = 0;
        h.has_hello = true;
        h.hello_interval_ms = uint32_t((long long)p.hello_interval_ms);
        broadcast(now, Message::of(h), LOCAL_TTL, out);
    } else {
        next_hello = now + p.hello_interval;
    }
}

// == maintenance (aodv/maintenance.py, RFC 6.11-6.12) ======================================
void AodvCore::link_break(double now, Addr nbr, Out& out) {
    // RFC 6.11 (i): every valid route through the neighbour; its number incremented if valid.
    std::vector<Route*> broken = table.via(nbr);
    for (Route* r : broken) {
        if (r->valid_seq) r->seq = seqnum::increment(r->seq);
        invalidate(*r, now);
    }
    std::vector<Route*> report;
    for (Route* r : broken) {
        // RFC 6.12: local repair. Decision: routes others use through us (precursors) that
        // carried data lately, not too far, not already being discovered, not rebooting.
        if (p.local_repair && !r->precursors.empty() && r->active_until > now &&
            r->hops <= p.max_repair_ttl && !discoveries.contains(r->dest) && !rebooting) {
            start_repair(now, *r, out);
        } else if (!r->precursors.empty()) {
            report.push_back(r);
        }
    }
    send_rerr(now, report, out, false);
}

void AodvCore::forward_without_route(double now, Addr dst, std::string packet, Out& out) {
    // RFC 6.11 (ii); RFC 6.12: during local repair data is buffered.
    Discovery* d = discoveries.find(dst);
    if (d != nullptr && d->is_repair) {
        buffer(dst, std::move(packet), out);
        return;
    }
    // RFC 6.13: a rebooted node resets its waiting timer.
    if (rebooting) reboot_until = now + p.delete_period;
    Route* r = table.get(dst);
    if (r == nullptr) {
        // Decision: with no entry the RERR carries sequence number 0.
        Route n;
        n.dest = dst;
        n.next_hop = dst;
        n.hops = 0;
        n.seq = 0;
        n.valid_seq = false;
        n.lifetime = now + p.delete_period;
        n.valid = false;
        r = table.add(std::move(n));
    } else if (r->valid_seq) {
        // RFC 6.11: incremented for cases (i) and (ii).
        r->seq = seqnum::increment(r->seq);
        r->lifetime = pymax(r->lifetime, now + p.delete_period);
    }
    // Decision: with no precursor known the RERR is broadcast with TTL 1.
    send_rerr(now, std::vector<Route*>{r}, out, true);
}

void AodvCore::on_rerr(double now, Addr src, const Rerr& m, Out& out) {
    // RFC 6.11 (iii): the listed destinations whose route goes through the RERR's sender.
    std::vector<Route*> affected;
    for (const auto& [dest, s] : m.unreachable) {
        Route* r = table.valid(dest);
        if (r == nullptr || r->next_hop != src) continue;
        affected.push_back(r);
        if (m.no_delete) continue;
        // Decision: the route is invalidated whatever the number; the number only moves
        // forward (RFC 6.1).
        if (!r->valid_seq || seqnum::newer(s, r->seq)) r->seq = s;
        r->valid_seq = true;
        invalidate(*r, now);
    }
    if (rebooting) return;
    // RFC 6.11: pass on those with precursors; RFC 6.12: a RERR with N likewise, with N.
    std::vector<Route*> routes;
    for (Route* r : affected)
        if (!r->precursors.empty()) routes.push_back(r);
    send_rerr(now, routes, out, false, m.no_delete);
}

void AodvCore::send_rerr(double now, const std::vector<Route*>& routes, Out& out, bool fallback,
                         bool no_delete) {
    if (routes.empty()) return;
    // RFC 6.11: RERR_RATELIMIT. Decision: RERRs over the limit are dropped (and counted).
    if (!rerr_limit_.allow(now)) {
        dropped["rerr_ratelimit"] += 1;
        return;
    }
    // RFC 6.11: unicast to a lone precursor, else the limited broadcast with TTL 1.
    std::vector<Addr> targets;
    for (Route* r : routes)
        for (Addr a : r->precursors)
            if (std::find(targets.begin(), targets.end(), a) == targets.end()) targets.push_back(a);
    for (size_t i = 0; i < routes.size(); i += 255) {
        Rerr e;
        e.no_delete = no_delete;
        for (size_t k = i; k < routes.size() && k < i + 255; ++k)
            e.unreachable.emplace_back(routes[k]->dest, routes[k]->seq);
        if (targets.size() == 1) {
            Action a;
            a.kind = Act::Unicast;
            a.msg = Message::of(e);
            a.addr = targets[0];
            a.ttl = LOCAL_TTL;
            out.push_back(std::move(a));
        } else if (!targets.empty() || fallback) {
            broadcast(now, Message::of(e), LOCAL_TTL, out);
        }
    }
}

void AodvCore::start_repair(double now, Route& r, Out& out) {
    // RFC 6.12: TTL max(MIN_REPAIR_TTL, 0.5 * #hops) + LOCAL_ADD_TTL. Decision: #hops is
    // the longest route among the precursors' plus one.
    long long far = 0;
    bool any = false;
    for (Addr pr : r.precursors) {
        Route* u = table.valid(pr);
        if (u != nullptr) {
            if (!any || u->hops > far) far = u->hops;
            any = true;
        }
    }
    if (!any) far = 1;
    far += 1;
    long long half = far >= 0 ? far / 2 : -((-far + 1) / 2);  // Python floor division by 2
    long long ttl = std::min(std::max((long long)r.hops, half) + p.local_add_ttl, p.net_diameter);
    Discovery d;
    d.dest = r.dest;
    d.ttl = ttl;
    d.started = now;
    d.is_repair = true;
    d.repair_hops = r.hops;
    Discovery& dd = discoveries.assign(r.dest, d);
    send_rreq(now, dd, out);
}

void AodvCore::repaired(double now, const Discovery& d, Route& r, Out& out) {
    // RFC 6.12: a longer route after a repair: RERR with N.
    if (d.is_repair && r.hops > d.repair_hops && !r.precursors.empty())
        send_rerr(now, std::vector<Route*>{&r}, out, false, true);
}

void AodvCore::repair_failed(double now, Addr dest, Out& out) {
    // RFC 6.12: no route at the end of the repair: RERR as in 6.11. Decision: the period is
    // one RING_TRAVERSAL_TIME of the repair's TTL.
    Discovery d = *discoveries.find(dest);
    discoveries.erase(dest);
    end_discovery(now, dest, d.started, d.round_started, false, true, out);
    Route* r = table.get(dest);
    if (r != nullptr && !r->precursors.empty()) send_rerr(now, std::vector<Route*>{r}, out, false);
}

void AodvCore::expire_routes(double now) {
    // RFC 6.11 / section 2: a valid route past its lifetime becomes invalid; an invalid one
    // is deleted after DELETE_PERIOD.
    for (Route* r : table.snapshot()) {
        if (r->lifetime <= now) {
            if (r->valid)
                invalidate(*r, now);
            else
                table.remove(r->dest);
        }
    }
}

// == datapath (aodv/datapath.py) ============================================================
void AodvCore::used(double now, Addr a) {
    // RFC 6.2: the route, and the route to its next hop, live ACTIVE_ROUTE_TIMEOUT longer.
    Route* r = table.valid(a);
    if (r != nullptr) {
        refresh(*r, now + p.active_route_timeout);
        Route* nh = table.valid(r->next_hop);
        if (nh != nullptr) refresh(*nh, now + p.active_route_timeout);
    }
}

std::vector<Action> AodvCore::sync() {
    // Install/Delete actions that bring the kernel's copy in line with the valid entries:
    // the touched entries in table order, then those gone from the table in the copy's order.
    std::vector<Action> acts;
    std::vector<Addr> present, absent;
    auto install = [&](const Route& r) {
        std::pair<Addr, int> key{r.next_hop, r.hops};
        const auto* have = installed.find(r.dest);
        if (have == nullptr || *have != key) {
            installed.assign(r.dest, key);
            Action a;
            a.kind = Act::Install;
            a.addr = r.dest;
            a.next_hop = r.next_hop;
            a.hops = r.hops;
            acts.push_back(std::move(a));
        }
    };
    auto del = [&](Addr d) {
        installed.erase(d);
        Action a;
        a.kind = Act::Delete;
        a.addr = d;
        acts.push_back(std::move(a));
    };
    if (!table.take_touched(present, absent)) {
        size_t n_valid = 0;
        for (const auto& e : table.peek_all()) {
            if (e.value.valid) {
                ++n_valid;
                install(e.value);
            } else if (installed.contains(e.key)) {
                del(e.key);
            }
        }
        if (installed.size() > n_valid) {
            std::vector<Addr> gone;
            for (const auto& e : installed) {
                const Route* r = table.peek(e.key);
                if (r == nullptr || !r->valid) gone.push_back(e.key);
            }
            for (Addr d : gone) del(d);
        }
        return acts;
    }
    for (Addr d : present) {
        const Route* r = table.peek(d);
        if (r->valid)
            install(*r);
        else if (installed.contains(d))
            del(d);
    }
    std::vector<std::pair<uint64_t, Addr>> gone;
    for (Addr d : absent) {
        uint64_t st = installed.stamp(d);
        if (st != UINT64_MAX) gone.emplace_back(st, d);
    }
    std::sort(gone.begin(), gone.end());
    for (auto& g : gone) del(g.second);
    return acts;
}

}  // namespace aodv
