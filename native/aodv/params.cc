// See params.h; aodv/params.py is the reference, property by property.
#include "params.h"

#include <algorithm>
#include <cmath>

namespace aodv {

namespace {
// Python's max(a, b): a unless b > a (and min likewise), so ties keep the first.
double pymax(double a, double b) { return b > a ? b : a; }
// Python's floor division of integers.
long long floordiv(long long a, long long b) {
    long long q = a / b;
    if ((a % b != 0) && ((a < 0) != (b < 0))) --q;
    return q;
}
}  // namespace

void Params::derive() {
    active_route_timeout = s(active_route_timeout_ms);
    hello_interval = s(hello_interval_ms);
    node_traversal_time = s(node_traversal_time_ms);
    net_traversal_time = 2 * node_traversal_time * double(net_diameter);
    path_discovery_time = 2 * net_traversal_time;
    if (blacklist_timeout_ms) {
        blacklist_timeout = s(*blacklist_timeout_ms);
    } else {
        long long rings = floordiv(ttl_threshold - ttl_start, ttl_increment) + 1;
        blacklist_timeout = double(rings + rreq_retries) * net_traversal_time;
    }
    delete_period = double(delete_period_k) * pymax(active_route_timeout, hello_interval);
    my_route_timeout = my_route_timeout_ms
                           ? s(*my_route_timeout_ms)
                           : 2 * pymax(active_route_timeout, path_discovery_time);
    next_hop_wait = node_traversal_time + s(10);
    neighbor_timeout = double(allowed_hello_loss) * hello_interval;
    max_repair_ttl = (long long)(0.3 * double(net_diameter));
    rate_window = s(1000);
}

unsigned long Params::ms(double seconds) const {
    double x = std::nearbyint(seconds * time_scale * 1000);  // round half to even
    if (!(x > 0)) return 0;
    if (x >= 4294967295.0) return 0xFFFFFFFFUL;
    return (unsigned long)x;
}

bool profile(const std::string& name, double time_scale, Params& out) {
    Params p;
    p.time_scale = time_scale;
    if (!gen::apply_profile(name, p)) return false;  // aodv/params.py's PROFILES
    p.derive();
    out = p;
    return true;
}

}  // namespace aodv
