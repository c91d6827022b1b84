// See control.h.
#include "control.h"

#include <cstring>
#include <unistd.h>

#include "kernel.h"
#include "log.h"

namespace aodv {

namespace {
const char* LOG = "aodv.daemon";
}

const char* type_name(const Message& m) {
    switch (m.type) {
        case RREQ_TYPE: return "RREQ";
        case RREP_TYPE: return "RREP";
        case RERR_TYPE: return "RERR";
        default: return "RREP-ACK";
    }
}

int open_control_socket(const std::string& iface, Addr addr) {
    int s = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    if (s < 0) throw KernelError(std::string("control socket: ") + strerror(errno));
    int one = 1, rcvbuf = 1 << 20;
    sockaddr_in sa{};
    sa.sin_family = AF_INET;
    sa.sin_port = htons(uint16_t(gen::AODV_PORT));
    const char* step = "";
    if ((step = "SO_REUSEADDR", setsockopt(s, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one)) ||
        (step = "SO_BINDTODEVICE",
         setsockopt(s, SOL_SOCKET, SO_BINDTODEVICE, iface.c_str(), socklen_t(iface.size()))) ||
        (step = "SO_BROADCAST", setsockopt(s, SOL_SOCKET, SO_BROADCAST, &one, sizeof one)) ||
        (step = "SO_RCVBUF", setsockopt(s, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof rcvbuf)) ||
        (step = "IP_RECVTTL", setsockopt(s, IPPROTO_IP, gen::RECVTTL_OPTION, &one, sizeof one)) ||
        (step = "bind UDP 654", bind(s, reinterpret_cast<sockaddr*>(&sa), sizeof sa))) {
        int e = errno;
        close(s);
        throw KernelError(std::string(step) + ": " + strerror(e));
    }
    try {
        drop_own_datagrams(s, addr);
    } catch (...) {
        close(s);
        throw;
    }
    return s;
}

void ControlChannel::send(const Message& msg, Addr dst, int ttl, int flags) {
    std::string data;
    try {
        data = encode(msg);
    } catch (const std::exception& e) {  // a core bug: count it, and let the route actions run
        stats_.dropped["encode_failed"] += 1;
        AODV_LOG(ERROR, LOG, "could not encode %s to %s: %s", type_name(msg),
                 addr_str(dst).c_str(), e.what());
        return;
    }
    if (ttl != ttl_) {
        setsockopt(sock_, IPPROTO_IP, IP_TTL, &ttl, sizeof ttl);
        ttl_ = ttl;
    }
    if (msg.type == RREQ_TYPE && msg.rreq.orig == addr_) {
        std::lock_guard<std::mutex> lock(rreq_mu_);
        rreq_sent_[msg.rreq.dest] = mono_now();
    }
    sockaddr_in to{};
    to.sin_family = AF_INET;
    to.sin_port = htons(uint16_t(gen::AODV_PORT));
    to.sin_addr.s_addr = htonl(dst);
    if (sendto(sock_, data.data(), data.size(), flags, reinterpret_cast<sockaddr*>(&to),
               sizeof to) < 0) {
        int e = errno;
        stats_.dropped["send_failed"] += 1;
        AODV_LOG(WARNING, LOG, "send %s to %s failed: %s", type_name(msg),
                 addr_str(dst).c_str(), strerror(e));
        return;
    }
    stats_.sent[is_hello(msg, addr_) ? "HELLO" : type_name(msg)] += 1;
    stats_.bytes_sent += (long long)data.size();
}

bool ControlChannel::pop_rreq_sent(Addr dest, double& when) {
    std::lock_guard<std::mutex> lock(rreq_mu_);
    auto it = rreq_sent_.find(dest);
    if (it == rreq_sent_.end()) return false;
    when = it->second;
    rreq_sent_.erase(it);
    return true;
}

void ControlChannel::read_icmp() {
    uint8_t buf[2048];
    for (int k = 0; k < 64; ++k) {
        ssize_t n = recv(icmp_, buf, sizeof buf, MSG_DONTWAIT);
        if (n < 0) {
            if (errno == EINTR) continue;
            return;
        }
        int udp_len = 0;
        std::string payload;
        if (!quoted_datagram(buf, size_t(n), addr_, udp_len, payload)) continue;
        Message m;
        const char* kind =
            decode(reinterpret_cast<const uint8_t*>(payload.data()), payload.size(), m)
                ? type_name(m)
                : "unknown";
        stats_.not_transmitted[kind] += 1;
        stats_.bytes_not_transmitted += udp_len - 8;
        AODV_LOG(INFO, LOG, "a %s of ours was not transmitted (ICMP destination unreachable)",
                 kind);
    }
}

}  // namespace aodv
