// The compiled AODV daemon: start-up, the loop, teardown (aodv/daemon.py is the reference).
//
// Theory of operation
// -------------------
// One thread serves the protocol: one ppoll(2) loop over the daemon's file descriptors,
// whose timeout is the core's next deadline (or the next route-use poll or statistics
// rewrite, if sooner), to the nanosecond. The descriptors: the UDP socket on port 654
// (control messages), the TUN device (data packets that found no kernel route), rtnetlink
// (the kernel's answers to failed route requests), the route-use reader (NETLINK_NETFILTER)
// and a raw ICMP socket. Signals (SIGTERM, SIGINT: stop; SIGUSR1: statistics now) are
// blocked everywhere but inside ppoll, which they interrupt; no wake-up pipe is needed.
//
//     UDP 654 datagram  -> decode -> core.on_control(src, ttl)   Unicast/Broadcast -> sendto
//     TUN packet        -> core.on_no_route(src, dst)            Install/Delete -> netlink
//     nft "used" set    -> core.on_routes_used(addrs)            Release -> raw socket
//     deadline reached  -> core.on_timer()                       Drop -> ICMP via TUN
//
// Two more threads keep the loop off slow system calls, as in the Python daemon: the
// actuator's kernel thread (route changes and what follows them, actuator.h) and the
// statistics writer (stats.h); log lines go through a third (log.h). The loop runs at
// common/sched.py's DEADLINE_PRIORITY (SCHED_RR 1, else nice -5, else as it is).
//
// Peer input is never trusted: a datagram that does not decode, or names an address outside
// the ad hoc network, is counted in dropped["malformed"] and logged (rate-limited); what the
// core bounds or refuses is counted in protocol_dropped.
//
// Start-up makes each kernel object followed by what undoes it; teardown undoes them in the
// reverse order, each failure logged and the rest still run: the kernel thread's last
// batches, the sockets (after reading the last ICMP errors), the nftables table and the
// route-use reader (whose socket made and removes it), the TUN device, our routes, the last
// statistics (indented), rtnetlink.
#include "daemon.h"

#include <arpa/inet.h>
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstring>
#include <functional>
#include <memory>
#include <netinet/in.h>
#include <poll.h>
#include <sched.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <unistd.h>
#include <unordered_set>

#include "../core.h"
#include "actuator.h"
#include "aodv_consts.h"
#include "control.h"
#include "kernel.h"
#include "log.h"
#include "stats.h"

namespace aodv {

namespace {
const char* LOG = "aodv.daemon";

volatile sig_atomic_t g_stop = 0;
volatile sig_atomic_t g_dump = 0;
void on_stop(int) { g_stop = 1; }
void on_dump(int) { g_dump = 1; }

// What start-up made, undone in reverse order; each step's failure logged, the rest run.
class Undo {
  public:
    void push(const char* what, std::function<void()> fn) { steps_.emplace_back(what, fn); }
    void run() {
        while (!steps_.empty()) {
            auto [what, fn] = std::move(steps_.back());
            steps_.pop_back();
            try {
                fn();
            } catch (const std::exception& e) {
                AODV_LOG(WARNING, LOG, "teardown: %s: %s", what, e.what());
            }
        }
    }

  private:
    std::vector<std::pair<const char*, std::function<void()>>> steps_;
};

int raw_socket(int proto, bool nonblocking) {
    int s = socket(AF_INET, SOCK_RAW | SOCK_CLOEXEC | (nonblocking ? SOCK_NONBLOCK : 0), proto);
    if (s < 0) throw KernelError(std::string("raw socket: ") + strerror(errno));
    return s;
}

class Daemon {
  public:
    Daemon(const Args& a, const Params& p) : args_(a), p_(p) {}
    int run();

  private:
    void start(Undo& undo);
    void loop();
    void dispatch(int timeout_ns_unused, const timespec* ts);
    void on_udp();
    void on_tun();
    void on_poll_answer();
    void poll_use(double now);
    bool check_addresses(Addr src, const Message& m, std::string& why);
    void drop(const char* reason, Addr src, const std::string& why);
    void update_stats();
    void rewrite_stats();
    void write_final_stats();
    bool has_routes() const;
    double poll_period() const { return p_.active_route_timeout / 3; }

    const Args& args_;
    Params p_;
    Addr addr_ = 0;
    std::unique_ptr<KernelRoutes> routes_;
    std::unique_ptr<Stats> stats_;
    std::unique_ptr<StatsWriter> writer_;
    std::unique_ptr<CounterStore> store_;
    std::unique_ptr<Tun> tun_;
    std::unique_ptr<SetReader> reader_;
    int sock_ = -1, raw_ = -1, icmp_ = -1;
    std::unique_ptr<ControlChannel> control_;
    std::unique_ptr<AodvCore> core_;
    std::unique_ptr<Actuator> actuator_;
    std::unordered_set<Addr> hosts_;  // addresses check_addresses found in our network
    long long malformed_logged_ = 0;
    double poll_started_ = 0;
    // Not zeroed: its pages are resident only once packets used them.
    std::unique_ptr<uint8_t[]> tun_buf_{new uint8_t[65535]};
};

int Daemon::run() {
    Undo undo;
    undo.push("log", [] { AODV_LOG(INFO, LOG, "AODV down"); });
    try {
        start(undo);
        loop();
    } catch (...) {
        undo.run();
        throw;
    }
    undo.run();
    return 0;
}

void Daemon::start(Undo& undo) {
    routes_ = std::make_unique<KernelRoutes>(args_.iface);
    undo.push("close rtnetlink", [this] { routes_->close(); });
    addr_ = routes_->address();
    stats_ = std::make_unique<Stats>(args_.robot, addr_str(addr_));
    undo.push("write statistics", [this] { write_final_stats(); });
    if (args_.has_stats) writer_ = std::make_unique<StatsWriter>(args_.stats);
    if (args_.has_state) store_ = std::make_unique<CounterStore>(args_.state);
    auto stale = routes_->ours();
    uint32_t seq = 0, rreq_id = 0;
    bool resumed = store_ && store_->load(seq, rreq_id);
    bool rebooted = !stale.empty() || resumed;
    if (!stale.empty())
        AODV_LOG(WARNING, LOG, "found %zu routes of a previous run: reboot rule applies",
                 stale.size());
    if (resumed)
        AODV_LOG(WARNING, LOG,
                 "restarted (counters of a previous instance found): waiting DELETE_PERIOD "
                 "(%.1f s), sequence number resumes at %u, RREQ ID at %u",
                 p_.delete_period, seq, rreq_id);
    routes_->flush();
    undo.push("flush routes", [this] { routes_->flush(); });
    tun_ = std::make_unique<Tun>(gen::TUN_NAME);
    undo.push("close the TUN device", [this] { tun_->close(); });
    routes_->catch_all(tun_->ifindex(), args_.net_addr, args_.net_prefix, addr_);
    reader_ = std::make_unique<SetReader>();
    undo.push("close the route-use reader", [this] { reader_->close(); });
    UseMonitor(reader_->fd(), args_.iface, args_.net_addr, args_.net_prefix, poll_period());
    undo.push("remove the route-use set", [this] { UseMonitor::remove(reader_->fd()); });
    sock_ = open_control_socket(args_.iface, addr_);
    undo.push("close the control socket", [this] { close(sock_); });
    raw_ = raw_socket(IPPROTO_RAW, false);
    undo.push("close the raw socket", [this] { close(raw_); });
    icmp_ = raw_socket(IPPROTO_ICMP, true);
    undo.push("close the ICMP socket", [this] { close(icmp_); });
    control_ = std::make_unique<ControlChannel>(sock_, icmp_, addr_, *stats_);
    // Run before the sockets close, so what the kernel reported meanwhile is counted.
    undo.push("read the last ICMP errors", [this] { control_->read_icmp(); });
    core_ = std::make_unique<AodvCore>(addr_, p_, mono_now(), rebooted, seq, rreq_id);
    if (store_) store_->cover(seq, rreq_id);  // a restart's own file says so from now on
    actuator_ = std::make_unique<Actuator>(*core_, *control_, *routes_, raw_, *tun_, *stats_,
                                           store_.get());
    // Undone first: the kernel thread's last batches reach the kernel before the routes are
    // flushed and the sockets closed.
    undo.push("finish the kernel thread's batches", [this] { actuator_->close(); });
    AODV_LOG(INFO, LOG, "AODV up on %s (%s), time scale %s", args_.iface.c_str(),
             addr_str(addr_).c_str(), [this] {
                 char b[32];
                 snprintf(b, sizeof b, "%g", p_.time_scale);
                 return std::string(b);
             }().c_str());
}

void Daemon::loop() {
    // The HELLO and expiry timers are the daemon's deadlines: real-time priority while the
    // loop serves; back as it was when it ends (common/sched.py deadline_priority).
    int policy = sched_getscheduler(0);
    sched_param param{};
    sched_getparam(0, &param);
    errno = 0;
    int niceness = getpriority(PRIO_PROCESS, 0);
    std::string got = raise_priority(gen::DEADLINE_RT_PRIORITY, gen::DEADLINE_NICE);
    AODV_LOG(DEBUG, LOG, "loop priority: %s", got.c_str());

    double next_poll = mono_now() + poll_period();
    double next_stats = mono_now();
    while (!g_stop) {
        double now = mono_now();
        double deadline = core_->next_deadline();
        if (now >= deadline) {
            bool hello = deadline == core_->next_hello;
            double late_ms = (now - deadline) * 1000 * p_.time_scale;
            (hello ? stats_->hello : stats_->expiry).add(late_ms, deadline, now);
            // What already waits in the sockets happened before the timer is handled.
            timespec zero{0, 0};
            dispatch(0, &zero);
            now = mono_now();
            actuator_->execute(core_->on_timer(now), now);
            deadline = core_->next_deadline();
        }
        // The route-use poll has something to ask only while a route is valid: without one
        // its deadline is none (an idle daemon sleeps through it), and it is set again, due
        // now, by the first event after which a route is valid.
        if (std::isinf(next_poll) && has_routes()) next_poll = now;
        if (now >= next_poll) {
            next_poll = has_routes() || reader_->busy ? now + poll_period() : INFINITY;
            poll_use(now);
        }
        if (g_dump || now >= next_stats) {
            g_dump = 0;
            next_stats = now + args_.stats_period;  // +inf with --stats-period 0
            rewrite_stats();
        }
        double wait = std::max(0.0, std::min({deadline, next_poll, next_stats}) - now);
        if (!(wait < 3600)) wait = 3600;  // never forever (a NaN deadline included)
        timespec ts;
        ts.tv_sec = time_t(wait);
        ts.tv_nsec = long((wait - double(ts.tv_sec)) * 1e9);
        if (ts.tv_nsec >= 1000000000L) ts.tv_nsec = 999999999L;
        dispatch(0, &ts);
    }
    sched_setscheduler(0, policy, &param);
    setpriority(PRIO_PROCESS, 0, niceness);
}

void Daemon::dispatch(int, const timespec* ts) {
    pollfd fds[5] = {{sock_, POLLIN, 0},
                     {tun_->fd(), POLLIN, 0},
                     {routes_->fd(), POLLIN, 0},
                     {reader_->fd(), POLLIN, 0},
                     {icmp_, POLLIN, 0}};
    sigset_t open_mask;
    sigemptyset(&open_mask);  // the signals are let in here only
    int n = ppoll(fds, 5, ts, &open_mask);
    if (n <= 0) return;  // timeout or a signal (EINTR)
    if (fds[0].revents) on_udp();
    if (fds[1].revents) on_tun();
    if (fds[2].revents) actuator_->read_route_acks();
    if (fds[3].revents) on_poll_answer();
    if (fds[4].revents) control_->read_icmp();
}

void Daemon::on_udp() {
    control_->receive([this](Addr src, int ttl, const uint8_t* data, size_t n) {
        Message msg;
        std::string why;
        if (!decode(data, n, msg, &why) || !check_addresses(src, msg, why)) {
            drop("malformed", src, why);
            return;
        }
        const char* kind = is_hello(msg, src) ? "HELLO" : type_name(msg);
        stats_->received[kind] += 1;
        double now = mono_now();
        try {
            actuator_->execute(core_->on_control(now, src, ttl, msg), now);
        } catch (const std::exception& e) {  // a bug must not kill the daemon; count it loudly
            stats_->dropped["error"] += 1;
            AODV_LOG(ERROR, LOG, "error handling %s from %s: %s", kind, addr_str(src).c_str(),
                     e.what());
        }
    });
}

bool Daemon::check_addresses(Addr src, const Message& m, std::string& why) {
    // Every address a peer names must be a host of our network (remembered once checked).
    Addr few[3] = {src, 0, 0};
    std::vector<Addr> many;
    const Addr* list = few;
    size_t count = 1;
    if (m.type == RREQ_TYPE) {
        few[1] = m.rreq.dest, few[2] = m.rreq.orig, count = 3;
    } else if (m.type == RREP_TYPE) {
        few[1] = m.rrep.dest, few[2] = m.rrep.orig, count = 3;
    } else if (m.type == RERR_TYPE) {
        many.push_back(src);
        for (const auto& u : m.rerr.unreachable) many.push_back(u.first);
        list = many.data();
        count = many.size();
    }
    Addr bcast = args_.net_addr | ~args_.net_mask;
    for (size_t k = 0; k < count; ++k) {
        Addr a = list[k];
        if (hosts_.count(a)) continue;
        if ((a & args_.net_mask) != args_.net_addr || a == args_.net_addr || a == bcast) {
            why = "address " + addr_str(a) + " outside " + args_.net;
            return false;
        }
        if (hosts_.size() >= size_t(gen::HOSTS_REMEMBERED)) hosts_.clear();
        hosts_.insert(a);
    }
    return true;
}

void Daemon::drop(const char* reason, Addr src, const std::string& why) {
    stats_->dropped[reason] += 1;
    long long n = ++malformed_logged_;
    if (n <= 10 || n % 10000 == 0)
        AODV_LOG(WARNING, LOG, "dropped %s datagram from %s (%lld so far): %s", reason,
                 addr_str(src).c_str(), n, why.c_str());
}

void Daemon::on_tun() {
    for (int k = 0; k < 256; ++k) {
        ssize_t n = tun_->read(tun_buf_.get(), 65535);
        if (n <= 0) return;
        const uint8_t* p = tun_buf_.get();
        if (n < 20 || (p[0] >> 4) != 4) {
            stats_->dropped["tun_not_ipv4"] += 1;
            continue;
        }
        uint32_t s, d;
        memcpy(&s, p + 12, 4);
        memcpy(&d, p + 16, 4);
        Addr src = ntohl(s), dst = ntohl(d);
        if ((dst & args_.net_mask) != args_.net_addr) {
            stats_->dropped["tun_foreign"] += 1;
            continue;
        }
        if (src == addr_) stats_->packets_buffered += 1;
        double now = mono_now();
        actuator_->execute(
            core_->on_no_route(now, src, dst, std::string(reinterpret_cast<const char*>(p), size_t(n))),
            now);
    }
}

bool Daemon::has_routes() const {
    for (const auto& e : core_->table.peek_all())
        if (e.value.valid) return true;
    return false;
}

void Daemon::poll_use(double now) {
    // Ask for the nftables set of used addresses, unless a request is under way; the answer
    // is read by the loop (on_poll_answer), which never blocks on it.
    if (reader_->busy && now - poll_started_ > 5 * poll_period()) {
        AODV_LOG(WARNING, LOG, "route-use poll got no answer; asking again");
        reader_->busy = false;
    }
    if (reader_->busy || !has_routes()) return;
    try {
        reader_->request();
    } catch (const KernelError& e) {
        AODV_LOG(WARNING, LOG, "route-use poll failed: %s", e.what());
        return;
    }
    poll_started_ = now;
}

void Daemon::on_poll_answer() {
    std::vector<Addr> used;
    try {
        if (!reader_->receive(used)) return;
    } catch (const KernelError& e) {
        reader_->busy = false;
        AODV_LOG(WARNING, LOG, "route-use poll: %s", e.what());
        return;
    }
    if (used.empty()) return;
    stats_->route_uses += (long long)used.size();
    actuator_->execute(core_->on_routes_used(poll_started_, used), mono_now());
}

void Daemon::update_stats() {
    if (!core_) return;  // start-up failed before the core was made
    stats_->routes.clear();
    for (const auto& e : core_->table.peek_all())
        if (e.value.valid)
            stats_->routes.push_back(
                {addr_str(e.key), {addr_str(e.value.next_hop), e.value.hops}});
    stats_->protocol_dropped.clear();
    for (const auto& [k, n] : core_->dropped) stats_->protocol_dropped[k] = n;
}

void Daemon::rewrite_stats() {
    // Handed to the writer's thread: the loop never waits on the file.
    if (!writer_) return;
    update_stats();
    writer_->submit(stats_->text(true));
}

void Daemon::write_final_stats() {
    if (writer_) writer_->close();
    if (!args_.has_stats) return;
    update_stats();
    std::string err;
    if (!json::write_atomic(args_.stats, stats_->text(false), &err))
        throw KernelError("statistics file " + args_.stats + " not written: " + err);
}

}  // namespace

int run_daemon(const Args& args, const Params& params) {
    struct sigaction sa {};
    sa.sa_handler = on_stop;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGTERM, &sa, nullptr);
    sigaction(SIGINT, &sa, nullptr);
    sa.sa_handler = on_dump;
    sigaction(SIGUSR1, &sa, nullptr);
    Daemon d(args, params);
    return d.run();
}

}  // namespace aodv
