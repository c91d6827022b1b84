// The control channel (aodv/control.py): RFC 3561 messages on UDP port 654 with their IP
// TTL. The socket is bound to 0.0.0.0:654 and to the interface, with SO_BROADCAST,
// IP_RECVTTL and the socket filter that drops our own broadcasts. `receive` reads up to 64
// datagrams with their source and TTL; `send` encodes a message and sends it with its TTL
// (set on the socket only when it changes; unicasts use MSG_DONTROUTE), counting it by kind;
// `read_icmp` counts the messages the kernel took but never transmitted.
#pragma once

#include <cstdint>
#include <map>
#include <mutex>
#include <string>

#include "../packet.h"
#include "stats.h"

namespace aodv {

int open_control_socket(const std::string& iface, Addr addr);

class ControlChannel {
  public:
    ControlChannel(int sock, int icmp, Addr addr, Stats& stats)
        : sock_(sock), icmp_(icmp), addr_(addr), stats_(stats) {}
    // Up to 64 datagrams: each (source, TTL, bytes) to `each`.
    template <class F>
    void receive(F&& each);
    void send(const Message& msg, Addr dst, int ttl, int flags);
    void read_icmp();
    // When our newest RREQ for `dest` went to sendto(); false if none (and forget it).
    bool pop_rreq_sent(Addr dest, double& when);

  private:
    int sock_, icmp_;
    Addr addr_;
    Stats& stats_;
    int ttl_ = -1;
    uint8_t rx_[4096];  // what receive() reads into (the loop's alone)
    std::mutex rreq_mu_;  // rreq_sent: written by the loop, read by the kernel thread
    std::map<Addr, double> rreq_sent_;
};

const char* type_name(const Message& m);

}  // namespace aodv

#include <arpa/inet.h>
#include <cstring>
#include <cerrno>
#include <netinet/in.h>
#include <sys/socket.h>

#include "aodv_consts.h"

namespace aodv {

template <class F>
void ControlChannel::receive(F&& each) {
    uint8_t* data = rx_;
    alignas(cmsghdr) char anc[CMSG_SPACE(sizeof(int)) + 64];
    for (int k = 0; k < 64; ++k) {
        sockaddr_in from{};
        iovec iov{data, sizeof rx_};
        msghdr mh{};
        mh.msg_name = &from;
        mh.msg_namelen = sizeof from;
        mh.msg_iov = &iov;
        mh.msg_iovlen = 1;
        mh.msg_control = anc;
        mh.msg_controllen = sizeof anc;
        ssize_t n = recvmsg(sock_, &mh, MSG_DONTWAIT);
        if (n < 0) {
            if (errno == EINTR) continue;
            return;
        }
        Addr src = ntohl(from.sin_addr.s_addr);
        if (src == addr_) continue;  // our own broadcast
        int ttl = 0;
        for (cmsghdr* c = CMSG_FIRSTHDR(&mh); c != nullptr; c = CMSG_NXTHDR(&mh, c))
            if (c->cmsg_level == IPPROTO_IP && c->cmsg_type == IP_TTL &&
                c->cmsg_len >= CMSG_LEN(sizeof(int)))
                memcpy(&ttl, CMSG_DATA(c), sizeof ttl);
        stats_.bytes_received += n;
        // A datagram longer than the buffer arrives cut (MSG_TRUNC): as Python's
        // recvmsg(4096), only the first 4096 bytes are decoded.
        each(src, ttl, data, size_t(n));
    }
}

}  // namespace aodv
