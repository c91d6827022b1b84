// Protocol parameters of RFC 3561 section 10 (aodv/params.py is the reference): the inputs
// with the RFC's defaults (times in RFC milliseconds) and every derived value in scaled
// seconds, computed with the same arithmetic, in the same order, as the Python properties
// (so each double is bit for bit the Python float). Profiles: "rfc" and "ns3".
#pragma once

#include <optional>
#include <string>

namespace aodv {

constexpr int MAX_TTL = 255;

struct Params {
    // -- inputs (aodv/params.py field names) --
    double time_scale = 1.0;
    double active_route_timeout_ms = 3000;
    long long allowed_hello_loss = 2;
    double hello_interval_ms = 1000;
    long long local_add_ttl = 2;
    long long net_diameter = 35;
    double node_traversal_time_ms = 40;
    long long rerr_ratelimit = 10;
    long long rreq_retries = 2;
    long long rreq_ratelimit = 10;
    long long timeout_buffer = 2;
    long long ttl_start = 2;
    long long ttl_increment = 2;
    long long ttl_threshold = 7;
    long long delete_period_k = 5;
    std::optional<double> my_route_timeout_ms;
    std::optional<double> blacklist_timeout_ms;
    bool local_repair = true;
    long long queue_len = 64;
    bool gratuitous_rrep = true;
    bool dest_only = false;
    long long route_table_limit = 1024;
    long long rreq_cache_limit = 4096;
    long long neighbor_limit = 256;
    long long rreq_forward_ratelimit = 100;

    // -- derived, in scaled seconds (call derive() after changing an input) --
    double active_route_timeout = 0, hello_interval = 0, node_traversal_time = 0;
    double net_traversal_time = 0, path_discovery_time = 0, blacklist_timeout = 0;
    double delete_period = 0, my_route_timeout = 0, next_hop_wait = 0;
    double neighbor_timeout = 0, rate_window = 0;
    long long max_repair_ttl = 0;

    void derive();
    // RFC milliseconds to scaled seconds: ms / 1000.0 / time_scale.
    double s(double ms) const { return ms / 1000.0 / time_scale; }
    // 2 * NODE_TRAVERSAL_TIME * (TTL_VALUE + TIMEOUT_BUFFER).
    double ring_traversal_time(long long ttl) const {
        return 2 * node_traversal_time * double(ttl + timeout_buffer);
    }
    // Scaled seconds to a Lifetime field: round half to even, clamped to 0..2**32-1.
    unsigned long ms(double seconds) const;
    double from_ms(double ms) const { return s(ms); }
};

// The named profile at a time scale (derived values computed); false for an unknown name.
bool profile(const std::string& name, double time_scale, Params& out);

}  // namespace aodv
