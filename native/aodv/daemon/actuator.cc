// See actuator.h.
#include "actuator.h"

#include <arpa/inet.h>
#include <cstdlib>
#include <cstring>
#include <sched.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include "aodv_consts.h"
#include "log.h"

namespace aodv {

namespace {
const char* LOG = "aodv.daemon";
constexpr size_t DISCOVERIES_KEPT = 1000;  // the statistics file keeps the newest 1000

bool realtime_off() {
    // common/envswitch.py: TESTBED_REALTIME, "1" (unset: the default) or "0", any case/space.
    const char* v = getenv("TESTBED_REALTIME");
    if (v == nullptr) return false;
    std::string t(v);
    while (!t.empty() && isspace((unsigned char)t.back())) t.pop_back();
    size_t a = 0;
    while (a < t.size() && isspace((unsigned char)t[a])) ++a;
    return t.substr(a) == "0";
}
}  // namespace

std::string raise_priority(int rt_priority, int nice) {
    if (!realtime_off()) {
        sched_param p{};
        p.sched_priority = rt_priority;
        // pid 0: the calling thread, as os.sched_setscheduler(0).
        if (sched_setscheduler(0, SCHED_RR | SCHED_RESET_ON_FORK, &p) == 0)
            return "SCHED_RR " + std::to_string(rt_priority);
    }
    if (setpriority(PRIO_PROCESS, id_t(syscall(SYS_gettid)), nice) == 0)
        return "nice " + std::to_string(nice);
    return "normal";
}

Actuator::Actuator(AodvCore& core, ControlChannel& control, KernelRoutes& routes, int raw,
                   Tun& tun, Stats& stats, CounterStore* store)
    : core_(core), control_(control), routes_(routes), raw_(raw), tun_(tun), stats_(stats),
      store_(store) {
    thread_ = std::thread([this] { run(); });
}

Actuator::~Actuator() { close(); }

void Actuator::close() {
    if (!thread_.joinable()) return;
    {
        std::lock_guard<std::mutex> lock(mu_);
        closing_ = true;
    }
    cv_.notify_one();
    thread_.join();
}

void Actuator::execute(std::vector<Action>&& actions, double now) {
    // RFC 6.13: the numbers these messages carry are on disk before they leave.
    if (store_) store_->cover(core_.seq, core_.rreq_id);
    // In the core's order: control messages leave here; the rest goes to the kernel thread
    // as one batch, in order.
    std::vector<Action> kernel;
    for (auto& a : actions) {
        if (a.kind == Act::Unicast)
            control_.send(a.msg, a.addr, a.ttl, MSG_DONTROUTE);
        else if (a.kind == Act::Broadcast)
            control_.send(a.msg, 0xFFFFFFFFu, a.ttl, 0);
        else
            kernel.push_back(std::move(a));
    }
    if (kernel.empty()) return;
    {
        std::lock_guard<std::mutex> lock(mu_);
        jobs_.push_back(Batch{std::move(kernel), now});
    }
    cv_.notify_one();
}

void Actuator::run() {
    raise_priority(gen::DEADLINE_RT_PRIORITY, gen::DEADLINE_NICE);
    for (;;) {
        Batch b;
        {
            std::unique_lock<std::mutex> lock(mu_);
            cv_.wait(lock, [this] { return !jobs_.empty() || closing_; });
            if (jobs_.empty()) return;  // closing, and everything carried out
            b = std::move(jobs_.front());
            jobs_.pop_front();
        }
        try {
            kernel_batch(b);
        } catch (const std::exception& e) {  // the routes must go on following the core
            AODV_LOG(ERROR, LOG, "kernel batch failed: %s", e.what());
        }
    }
}

bool Actuator::route_change(bool install, const Action& a) {
    try {
        if (install) routes_.install(a.addr, a.next_hop);
        else routes_.remove(a.addr);
        return true;
    } catch (const KernelError& e) {
        std::lock_guard<std::mutex> lock(stats_.kmu);
        stats_.k.dropped["route_send_failed"] += 1;
        AODV_LOG(WARNING, LOG, "%s", e.what());
        return false;
    }
}

void Actuator::kernel_batch(Batch& b) {
    double routed = b.now;  // when the last route change of this batch was in the kernel
    uint32_t own = htonl(core_.addr);
    for (auto& a : b.actions) {
        switch (a.kind) {
            case Act::Install: {
                bool ok = route_change(true, a);
                routed = mono_now();
                if (ok) {
                    std::lock_guard<std::mutex> lock(stats_.kmu);
                    stats_.k.route_installs += 1;
                }
                AODV_LOG(DEBUG, LOG, "route %s via %s (%d hops)", addr_str(a.addr).c_str(),
                         addr_str(a.next_hop).c_str(), a.hops);
                break;
            }
            case Act::Delete: {
                bool ok = route_change(false, a);
                routed = mono_now();
                if (ok) {
                    std::lock_guard<std::mutex> lock(stats_.kmu);
                    stats_.k.route_deletes += 1;
                }
                AODV_LOG(DEBUG, LOG, "route %s deleted", addr_str(a.addr).c_str());
                break;
            }
            case Act::Release: {
                sockaddr_in to{};
                to.sin_family = AF_INET;
                to.sin_addr.s_addr = htonl(a.addr);
                for (const auto& pkt : a.packets) {
                    bool ok = sendto(raw_, pkt.data(), pkt.size(), 0,
                                     reinterpret_cast<sockaddr*>(&to), sizeof to) >= 0;
                    int e = errno;
                    std::lock_guard<std::mutex> lock(stats_.kmu);
                    if (ok) {
                        stats_.k.packets_released += 1;
                    } else {
                        stats_.k.dropped["release_failed"] += 1;
                        AODV_LOG(WARNING, LOG, "re-send to %s failed: %s",
                                 addr_str(a.addr).c_str(), strerror(e));
                    }
                }
                break;
            }
            case Act::Drop:
                for (const auto& pkt : a.packets) {
                    if (pkt.size() >= 20 && memcmp(pkt.data() + 12, &own, 4) == 0) {
                        tun_.write(icmp_host_unreachable(core_.addr, pkt));
                        std::lock_guard<std::mutex> lock(stats_.kmu);
                        stats_.k.icmp_unreachable += 1;
                    }
                }
                break;
            case Act::Done:
                if (a.repair) {
                    {
                        std::lock_guard<std::mutex> lock(stats_.kmu);
                        stats_.k.local_repairs[a.ok ? "ok" : "failed"] += 1;
                    }
                    AODV_LOG(INFO, LOG, "local repair of %s %s", addr_str(a.addr).c_str(),
                             a.ok ? "succeeded" : "failed");
                } else {
                    discovery_done(a, b.now, routed);
                }
                break;
            default:
                break;
        }
    }
}

void Actuator::discovery_done(const Action& a, double now, double routed) {
    // Both latencies end when the route is in the kernel; the round starts when the RREQ
    // that succeeded went to sendto() (aodv/actuator.py).
    double extra = routed - now, sent;
    double rnd = control_.pop_rreq_sent(a.addr, sent) ? routed - sent : a.round_latency + extra;
    DiscoveryRecord d{addr_str(a.addr), a.ok, json::py_round(a.latency + extra, 6),
                json::py_round(rnd, 6), json::py_round(wall_now(), 3)};
    {
        std::lock_guard<std::mutex> lock(stats_.kmu);
        (a.ok ? stats_.k.discoveries_ok : stats_.k.discoveries_failed) += 1;
        stats_.k.discoveries.push_back(d);
        if (stats_.k.discoveries.size() > DISCOVERIES_KEPT) stats_.k.discoveries.pop_front();
    }
    AODV_LOG(INFO, LOG, "discovery of %s %s after %.1f ms", d.dest.c_str(),
             a.ok ? "succeeded" : "failed", 1000 * (a.latency + extra));
}

void Actuator::read_route_acks() {
    for (const auto& failure : routes_.read_acks()) {
        {
            std::lock_guard<std::mutex> lock(stats_.kmu);
            stats_.k.dropped["kernel_route_error"] += 1;
        }
        AODV_LOG(WARNING, LOG, "kernel refused %s", failure.c_str());
    }
}

}  // namespace aodv
