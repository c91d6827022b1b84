// Protocol parameters of RFC 3561 section 10 (aodv/params.py is the reference): the inputs
// with the RFC's defaults (times in RFC milliseconds; written once, in Python, and generated
// from it) and every derived value in scaled seconds, computed with the same arithmetic, in the same order, as the Python properties
// (so each double is bit for bit the Python float). Profiles: "rfc" and "ns3".
#pragma once

#include <optional>
#include <string>

#include "aodv_params.h"  // generated: python -m aodv.constgen --params

namespace aodv {

constexpr int MAX_TTL = gen::MAX_TTL;

// The inputs (aodv/params.py's fields, with its defaults: gen::ParamInputs, generated from it
// into build/gen/aodv_params.h by aodv/constgen.py) and what they derive.
struct Params : gen::ParamInputs {
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
