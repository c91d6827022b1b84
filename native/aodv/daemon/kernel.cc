// See kernel.h; aodv/kernel.py and topology/kernel/netlinkmsg.py are the reference.
#include "kernel.h"

#include <algorithm>
#include <cstddef>
#include <arpa/inet.h>
#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <linux/filter.h>
#include <linux/if_tun.h>
#include <linux/netfilter.h>
#include <linux/netfilter/nf_tables.h>
#include <linux/netfilter/nfnetlink.h>
#include <linux/netlink.h>
#include <linux/rtnetlink.h>
#include <net/if.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include "aodv_consts.h"
#include "log.h"

namespace aodv {

namespace {
const char* LOG = "aodv.kernel";

std::string err_text(int code) { return strerror(code); }

double mono() {
    timespec ts{};
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return double(ts.tv_sec) + double(ts.tv_nsec) * 1e-9;
}

// -- netlink messages (netlinkmsg.py) ----------------------------------------------------
struct Msg {
    std::vector<uint8_t> b;
    Msg(uint16_t type, uint16_t flags, uint32_t seq) {
        nlmsghdr h{};
        h.nlmsg_type = type;
        h.nlmsg_flags = flags;
        h.nlmsg_seq = seq;
        put(&h, sizeof h);
    }
    void put(const void* p, size_t n) {
        const uint8_t* c = static_cast<const uint8_t*>(p);
        b.insert(b.end(), c, c + n);
    }
    void attr(uint16_t type, const void* v, size_t n) {
        uint16_t hdr[2] = {uint16_t(4 + n), type};
        put(hdr, 4);
        put(v, n);
        b.resize(b.size() + ((4 - n % 4) % 4), 0);
    }
    void u32(uint16_t type, uint32_t v) { attr(type, &v, 4); }
    void addr(uint16_t type, Addr a) {
        uint32_t n = htonl(a);
        attr(type, &n, 4);
    }
    void str(uint16_t type, const std::string& s) { attr(type, s.c_str(), s.size() + 1); }
    void be32(uint16_t type, uint32_t v) { u32(type, htonl(v)); }
    void be64(uint16_t type, uint64_t v) {
        uint32_t w[2] = {htonl(uint32_t(v >> 32)), htonl(uint32_t(v))};
        attr(type, w, 8);
    }
    // A nested attribute: begin() before its members, end() with what begin() returned.
    size_t begin(uint16_t type) {
        size_t at = b.size();
        uint16_t hdr[2] = {0, uint16_t(type | NLA_F_NESTED)};
        put(hdr, 4);
        return at;
    }
    void end(size_t at) {
        uint16_t len = uint16_t(b.size() - at);
        memcpy(b.data() + at, &len, 2);
    }
    std::vector<uint8_t>& done() {
        uint32_t len = uint32_t(b.size());
        memcpy(b.data(), &len, 4);
        return b;
    }
};

Msg route_message(uint16_t type, uint16_t flags, Addr dest, int plen, uint8_t proto,
                  uint8_t scope, uint8_t rtype, uint32_t rflags, uint32_t seq) {
    Msg m(type, flags, seq);
    rtmsg r{};
    r.rtm_family = AF_INET;
    r.rtm_dst_len = uint8_t(plen);
    r.rtm_table = RT_TABLE_MAIN;
    r.rtm_protocol = proto;
    r.rtm_scope = scope;
    r.rtm_type = rtype;
    r.rtm_flags = rflags;
    m.put(&r, sizeof r);
    m.addr(RTA_DST, dest);
    return m;
}

// (type without flags, value start, value end) of each attribute in p[at:end].
template <class F>
void attrs(const uint8_t* p, size_t at, size_t end, F&& each) {
    while (at + 4 <= end) {
        uint16_t len, type;
        memcpy(&len, p + at, 2);
        memcpy(&type, p + at + 2, 2);
        if (len < 4) return;
        size_t stop = std::min(at + len, end);
        each(int(type & NLA_TYPE_MASK), at + 4, stop);
        at += (size_t(len) + 3) & ~size_t(3);
    }
}

// (type, seq, payload start, payload end) of each message of one datagram.
template <class F>
void each_message(const uint8_t* p, size_t n, F&& each) {
    size_t off = 0;
    while (off + sizeof(nlmsghdr) <= n) {
        nlmsghdr h;
        memcpy(&h, p + off, sizeof h);
        if (h.nlmsg_len < sizeof(nlmsghdr)) return;
        each(h.nlmsg_type, h.nlmsg_seq, off + sizeof h, std::min(off + h.nlmsg_len, n));
        off += (size_t(h.nlmsg_len) + 3) & ~size_t(3);
    }
}

int error_code(const uint8_t* p, size_t at) {
    int32_t e;
    memcpy(&e, p + at, 4);
    return -e;
}

int netlink_socket(int proto) {
    int fd = socket(AF_NETLINK, SOCK_RAW | SOCK_CLOEXEC | SOCK_NONBLOCK, proto);
    if (fd < 0) throw KernelError(std::string("netlink socket: ") + strerror(errno));
    sockaddr_nl sa{};
    sa.nl_family = AF_NETLINK;
    if (bind(fd, reinterpret_cast<sockaddr*>(&sa), sizeof sa) != 0) {
        int e = errno;
        ::close(fd);
        throw KernelError(std::string("netlink bind: ") + strerror(e));
    }
    return fd;
}

int ioctl_socket() {
    int s = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    if (s < 0) throw KernelError(std::string("socket: ") + strerror(errno));
    return s;
}

uint16_t checksum(const uint8_t* p, size_t n) {
    uint32_t s = 0;
    for (size_t k = 0; k + 1 < n; k += 2) s += uint32_t(p[k]) << 8 | p[k + 1];
    if (n % 2) s += uint32_t(p[n - 1]) << 8;
    s = (s >> 16) + (s & 0xFFFF);
    s += s >> 16;
    return uint16_t(~s & 0xFFFF);
}
}  // namespace

// -- helpers ---------------------------------------------------------------------------------
void write_sysctl(const std::string& path, const std::string& value) {
    std::string file = "/proc/sys/" + path;
    for (size_t k = 10; k < file.size(); ++k)
        if (file[k] == '.') file[k] = '/';
    int fd = open(file.c_str(), O_WRONLY | O_CLOEXEC);
    if (fd < 0 || ::write(fd, value.data(), value.size()) != ssize_t(value.size())) {
        int e = errno;
        if (fd >= 0) ::close(fd);
        throw KernelError("sysctl " + path + "=" + value + ": " + strerror(e));
    }
    ::close(fd);
}

int ifindex(const std::string& name) {
    unsigned idx = if_nametoindex(name.c_str());
    if (idx == 0) throw KernelError("no interface " + name);
    return int(idx);
}

Addr ipv4_address(const std::string& name) {
    int s = ioctl_socket();
    ifreq r{};
    strncpy(r.ifr_name, name.c_str(), IFNAMSIZ - 1);
    int rc = ioctl(s, SIOCGIFADDR, &r);
    ::close(s);
    if (rc != 0) throw KernelError(name + " has no IPv4 address");
    sockaddr_in sin;
    memcpy(&sin, &r.ifr_addr, sizeof sin);
    return ntohl(sin.sin_addr.s_addr);
}

void set_up(const std::string& name) {
    int s = ioctl_socket();
    ifreq r{};
    strncpy(r.ifr_name, name.c_str(), IFNAMSIZ - 1);
    int rc = ioctl(s, SIOCGIFFLAGS, &r);
    if (rc == 0) {
        r.ifr_flags = short(r.ifr_flags | IFF_UP);
        rc = ioctl(s, SIOCSIFFLAGS, &r);
    }
    int e = errno;
    ::close(s);
    if (rc != 0) throw KernelError("set " + name + " up: " + strerror(e));
}

void drop_own_datagrams(int fd, Addr own) {
    sock_filter prog[] = {
        {BPF_LD | BPF_W | BPF_ABS, 0, 0, uint32_t(SKF_NET_OFF + 12)},
        {BPF_JMP | BPF_JEQ | BPF_K, 1, 0, own},
        {BPF_RET | BPF_K, 0, 0, 0xFFFFFFFF},
        {BPF_RET | BPF_K, 0, 0, 0},
    };
    sock_fprog fprog{sizeof prog / sizeof prog[0], prog};
    if (setsockopt(fd, SOL_SOCKET, SO_ATTACH_FILTER, &fprog, sizeof fprog) != 0)
        throw KernelError(std::string("socket filter: ") + strerror(errno));
}

// -- KernelRoutes ----------------------------------------------------------------------------
KernelRoutes::KernelRoutes(const std::string& ifname)
    : ifname_(ifname), ifindex_(ifindex(ifname)), nl_(netlink_socket(NETLINK_ROUTE)) {}

KernelRoutes::~KernelRoutes() { close(); }

void KernelRoutes::close() {
    if (nl_ >= 0) ::close(nl_);
    nl_ = -1;
}

uint32_t KernelRoutes::next_seq(const std::string& what) {
    std::lock_guard<std::mutex> lock(pending_mu_);
    uint32_t seq = ++seq_;
    pending_[seq] = what;
    if (pending_.size() > size_t(gen::PENDING_MAX)) pending_.erase(pending_.begin());
    return seq;
}

void KernelRoutes::send(const std::vector<uint8_t>& msg, const std::string& what) {
    if (::send(nl_, msg.data(), msg.size(), 0) < 0)
        throw KernelError(what + ": " + strerror(errno));
}

template <class F>
void KernelRoutes::messages(int timeout_ms, F&& each) {
    if (timeout_ms > 0) {
        pollfd p{nl_, POLLIN, 0};
        if (poll(&p, 1, timeout_ms) <= 0) return;
    }
    uint8_t* buf = buf_.get();
    for (;;) {
        ssize_t n = recv(nl_, buf, BUF, 0);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) return;
        each_message(buf, size_t(n), [&](int type, uint32_t seq, size_t s, size_t e) {
            each(type, seq, buf, s, e);
        });
    }
}

std::string KernelRoutes::ack(uint32_t seq, int code) {
    std::string what = "?";
    {
        std::lock_guard<std::mutex> lock(pending_mu_);
        auto it = pending_.find(seq);
        if (it != pending_.end()) {
            what = it->second;
            pending_.erase(it);
        }
    }
    if (code && code != ESRCH && code != ENOENT) return what + ": " + err_text(code);
    return "";
}

std::vector<std::string> KernelRoutes::read_acks() {
    std::vector<std::string> failures;
    messages(0, [&](int type, uint32_t seq, const uint8_t* p, size_t s, size_t e) {
        if (type == NLMSG_ERROR && e - s >= 4) {
            std::string f = ack(seq, error_code(p, s));
            if (!f.empty()) failures.push_back(f);
        }
    });
    return failures;
}

void KernelRoutes::wait(uint32_t seq) {
    double deadline = mono() + 5.0;
    bool got = false;
    std::string failure;
    while (!got && mono() < deadline) {
        messages(50, [&](int type, uint32_t mseq, const uint8_t* p, size_t s, size_t e) {
            if (got || type != NLMSG_ERROR || e - s < 4) return;
            std::string f = ack(mseq, error_code(p, s));
            if (mseq == seq) {
                got = true;
                failure = f;
            } else if (!f.empty()) {
                AODV_LOG(WARNING, LOG, "kernel refused %s", f.c_str());
            }
        });
    }
    if (!got) {
        std::string what = "?";
        std::lock_guard<std::mutex> lock(pending_mu_);
        auto it = pending_.find(seq);
        if (it != pending_.end()) what = it->second, pending_.erase(it);
        throw KernelError("no answer from the kernel to " + what);
    }
    if (!failure.empty()) throw KernelError(failure);
}

std::vector<std::pair<Addr, int>> KernelRoutes::ours() {
    read_acks();
    uint32_t seq;
    {
        std::lock_guard<std::mutex> lock(pending_mu_);
        seq = ++seq_;
    }
    Msg m(RTM_GETROUTE, NLM_F_REQUEST | NLM_F_DUMP, seq);
    rtmsg r{};
    r.rtm_family = AF_INET;
    m.put(&r, sizeof r);
    send(m.done(), "dump");
    std::vector<std::pair<Addr, int>> found;
    bool done = false;
    double deadline = mono() + 5.0;
    while (!done && mono() < deadline) {
        messages(50, [&](int type, uint32_t mseq, const uint8_t* p, size_t s, size_t e) {
            if (done || mseq != seq) return;
            if (type == NLMSG_DONE || type == NLMSG_ERROR) {
                done = true;
                return;
            }
            if (type != RTM_NEWROUTE || e - s < sizeof(rtmsg)) return;
            rtmsg rt;
            memcpy(&rt, p + s, sizeof rt);
            if (rt.rtm_protocol != gen::RTPROT_AODV) return;
            Addr dst = 0;
            attrs(p, s + sizeof(rtmsg), e, [&](int kind, size_t vs, size_t ve) {
                if (kind == RTA_DST && ve - vs == 4) {
                    uint32_t n;
                    memcpy(&n, p + vs, 4);
                    dst = ntohl(n);
                }
            });
            found.emplace_back(dst, rt.rtm_dst_len);
        });
    }
    if (!done) throw KernelError("route dump did not finish");
    return found;
}

size_t KernelRoutes::flush() {
    auto found = ours();
    for (auto& [dst, plen] : found) wait(remove(dst, plen, true));
    return found.size();
}

uint32_t KernelRoutes::install(Addr dest, Addr next_hop, bool ack_) {
    std::string what = "route " + addr_str(dest) + " via " + addr_str(next_hop);
    uint32_t seq = next_seq(what);
    uint16_t flags = NLM_F_REQUEST | NLM_F_REPLACE | NLM_F_CREATE | (ack_ ? NLM_F_ACK : 0);
    if (next_hop == dest) {
        Msg m = route_message(RTM_NEWROUTE, flags, dest, 32, gen::RTPROT_AODV, RT_SCOPE_LINK,
                              RTN_UNICAST, 0, seq);
        m.u32(RTA_OIF, uint32_t(ifindex_));
        send(m.done(), what);
    } else {
        Msg m = route_message(RTM_NEWROUTE, flags, dest, 32, gen::RTPROT_AODV,
                              RT_SCOPE_UNIVERSE, RTN_UNICAST, RTNH_F_ONLINK, seq);
        m.u32(RTA_OIF, uint32_t(ifindex_));
        m.addr(RTA_GATEWAY, next_hop);
        send(m.done(), what);
    }
    return seq;
}

uint32_t KernelRoutes::remove(Addr dest, int plen, bool ack_) {
    std::string what = "delete route " + addr_str(dest);
    uint32_t seq = next_seq(what);
    Msg m = route_message(RTM_DELROUTE, NLM_F_REQUEST | (ack_ ? NLM_F_ACK : 0), dest, plen,
                          gen::RTPROT_AODV, RT_SCOPE_NOWHERE, 0, 0, seq);
    send(m.done(), what);
    return seq;
}

void KernelRoutes::catch_all(int oif, Addr net, int plen, Addr src) {
    std::string what = "route " + addr_str(net) + "/" + std::to_string(plen) + " dev TUN";
    uint32_t seq = next_seq(what);
    Msg m = route_message(RTM_NEWROUTE, NLM_F_REQUEST | NLM_F_ACK | NLM_F_REPLACE | NLM_F_CREATE,
                          net, plen, gen::RTPROT_AODV, RT_SCOPE_LINK, RTN_UNICAST, 0, seq);
    m.u32(RTA_OIF, uint32_t(oif));
    m.addr(RTA_PREFSRC, src);
    m.u32(RTA_PRIORITY, 1000);
    send(m.done(), what);
    wait(seq);
}

// -- Tun ---------------------------------------------------------------------------------------
Tun::Tun(const std::string& name) {
    fd_ = open("/dev/net/tun", O_RDWR | O_NONBLOCK | O_CLOEXEC);
    if (fd_ < 0) throw KernelError("create TUN " + name + ": " + strerror(errno));
    ifreq r{};
    strncpy(r.ifr_name, name.c_str(), IFNAMSIZ - 1);
    r.ifr_flags = IFF_TUN | IFF_NO_PI;
    if (ioctl(fd_, TUNSETIFF, &r) != 0) {
        int e = errno;
        close();
        throw KernelError("create TUN " + name + ": " + strerror(e));
    }
    try {
        // docs/architecture.md: the daemon ignores IPv6 and disables it on its TUN device.
        write_sysctl("net.ipv6.conf." + name + ".disable_ipv6", "1");
        // ICMP errors we inject come from our own address: accept them on the TUN.
        write_sysctl("net.ipv4.conf." + name + ".accept_local", "1");
        write_sysctl("net.ipv4.conf." + name + ".rp_filter", "0");
        ifindex_ = aodv::ifindex(name);
        set_up(name);
    } catch (...) {
        close();
        throw;
    }
}

Tun::~Tun() { close(); }

void Tun::close() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
}

ssize_t Tun::read(uint8_t* buf, size_t n) {
    ssize_t r = ::read(fd_, buf, n);
    return r < 0 ? 0 : r;
}

bool Tun::write(const std::string& packet) {
    return ::write(fd_, packet.data(), packet.size()) == ssize_t(packet.size());
}

// -- UseMonitor ----------------------------------------------------------------------------
// aodv.kernel.UseMonitor's ruleset (the Python daemon gives it to `nft -f`), as the netlink
// messages nft makes of it (`nft --debug=netlink -f` lists them), sent as one nftables batch:
// no nft is forked (an exec of nft, its libraries and its parser were half of a daemon's
// start-up CPU). The batch first adds and deletes the table, so that a table a previous daemon
// left is replaced and a missing one is no error (a failed batch costs the kernel an RCU grace
// period). tests/integration/test_aodv_cpp_daemon.py holds `nft list table` of the two equal.
namespace {
constexpr uint16_t NFT_TYPE(int msg) { return uint16_t((NFNL_SUBSYS_NFTABLES << 8) | msg); }
constexpr uint32_t REG = 1;    // NFT_REG_1, as nft 1.0 writes it
constexpr uint32_t SET_ID = 1;  // the set, within the batch
constexpr uint32_t TYPE_IPADDR = 7;  // nft's datatype of ipv4_addr (informational)

Msg nft_message(int msg, uint16_t flags, uint32_t seq, uint8_t family = NFPROTO_IPV4,
                uint16_t res_id = 0) {
    Msg m(NFT_TYPE(msg), uint16_t(NLM_F_REQUEST | flags), seq);
    nfgenmsg g{};
    g.nfgen_family = family;
    g.version = NFNETLINK_V0;
    g.res_id = htons(res_id);
    m.put(&g, sizeof g);
    return m;
}

class Rule {
  public:
    Rule(Msg& m) : m_(m), list_(m.begin(NFTA_RULE_EXPRESSIONS)) {}
    ~Rule() { m_.end(list_); }
    void payload(uint32_t base, uint32_t offset, uint32_t len) {
        expr("payload", [&] {
            m_.be32(NFTA_PAYLOAD_DREG, REG);
            m_.be32(NFTA_PAYLOAD_BASE, base);
            m_.be32(NFTA_PAYLOAD_OFFSET, offset);
            m_.be32(NFTA_PAYLOAD_LEN, len);
        });
    }
    void meta(uint32_t key) {
        expr("meta", [&] {
            m_.be32(NFTA_META_DREG, REG);
            m_.be32(NFTA_META_KEY, key);
        });
    }
    void cmp_eq(const void* data, size_t n) {
        expr("cmp", [&] {
            m_.be32(NFTA_CMP_SREG, REG);
            m_.be32(NFTA_CMP_OP, NFT_CMP_EQ);
            value(NFTA_CMP_DATA, data, n);
        });
    }
    void mask(uint32_t mask_be) {
        uint32_t zero = 0;
        expr("bitwise", [&] {
            m_.be32(NFTA_BITWISE_SREG, REG);
            m_.be32(NFTA_BITWISE_DREG, REG);
            m_.be32(NFTA_BITWISE_LEN, 4);
            value(NFTA_BITWISE_MASK, &mask_be, 4);
            value(NFTA_BITWISE_XOR, &zero, 4);
        });
    }
    void ret() {
        expr("immediate", [&] {
            m_.be32(NFTA_IMMEDIATE_DREG, NFT_REG_VERDICT);
            size_t d = m_.begin(NFTA_IMMEDIATE_DATA);
            size_t v = m_.begin(NFTA_DATA_VERDICT);
            m_.be32(NFTA_VERDICT_CODE, uint32_t(NFT_RETURN));
            m_.end(v);
            m_.end(d);
        });
    }
    void update_used() {
        expr("dynset", [&] {
            m_.str(NFTA_DYNSET_SET_NAME, "used");
            m_.be32(NFTA_DYNSET_SET_ID, SET_ID);
            m_.be32(NFTA_DYNSET_OP, NFT_DYNSET_OP_UPDATE);
            m_.be32(NFTA_DYNSET_SREG_KEY, REG);
        });
    }
    // `ip daddr|saddr NET`, as nft compiles it: the prefix's whole bytes compared, or all
    // four under a mask where it does not end on a byte.
    void in_net(uint32_t offset, Addr net, int plen) {
        uint32_t be = htonl(net);
        if (plen > 0 && plen % 8 == 0) {
            payload(NFT_PAYLOAD_NETWORK_HEADER, offset, uint32_t(plen / 8));
            cmp_eq(&be, size_t(plen / 8));
        } else {
            payload(NFT_PAYLOAD_NETWORK_HEADER, offset, 4);
            mask(htonl(plen == 0 ? 0 : ~uint32_t(0) << (32 - plen)));
            cmp_eq(&be, 4);
        }
    }

  private:
    template <class F>
    void expr(const char* name, F&& data) {
        size_t e = m_.begin(NFTA_LIST_ELEM);
        m_.str(NFTA_EXPR_NAME, name);
        size_t d = m_.begin(NFTA_EXPR_DATA);
        data();
        m_.end(d);
        m_.end(e);
    }
    void value(uint16_t type, const void* data, size_t n) {
        size_t at = m_.begin(type);
        m_.attr(NFTA_DATA_VALUE, data, n);
        m_.end(at);
    }
    Msg& m_;
    size_t list_;
};

// Send one nftables batch over `fd` (its messages between BEGIN and END, each asking for an
// acknowledgement) and wait up to 5 s for every answer; the first refusal is thrown. The
// socket is the route-use reader's, kept open: closing a NETLINK_NETFILTER socket that sent a
// batch waits for the kernel to finish destroying the batch's transaction (an RCU grace
// period, 15 ms of a daemon's start-up). Its sequence numbers are apart from the reader's.
void nft_batch(int fd, std::vector<Msg>& messages, const std::string& what) {
    std::vector<uint8_t> batch;
    uint32_t seq = 0x80000000u;
    auto append = [&batch](Msg& m) {
        auto& b = m.done();
        batch.insert(batch.end(), b.begin(), b.end());
    };
    auto control = [&](uint16_t type) {  // BATCH_BEGIN and _END: not nftables messages
        Msg c = nft_message(0, 0, seq++, AF_UNSPEC, NFNL_SUBSYS_NFTABLES);
        memcpy(c.b.data() + offsetof(nlmsghdr, nlmsg_type), &type, 2);
        append(c);
    };
    control(NFNL_MSG_BATCH_BEGIN);
    uint32_t lo = seq;
    for (auto& m : messages) {
        uint32_t n = seq++;
        memcpy(m.b.data() + offsetof(nlmsghdr, nlmsg_seq), &n, 4);
        append(m);
    }
    uint32_t hi = seq;
    control(NFNL_MSG_BATCH_END);
    std::string failure;
    if (::send(fd, batch.data(), batch.size(), 0) < 0) failure = strerror(errno);
    size_t answered = 0;
    // The answers are acknowledgements, one a datagram, each with at most the message it
    // answers: on the stack, so no page of the heap is made resident for them.
    uint8_t buf[8192];
    double deadline = mono() + 5.0;
    while (failure.empty() && answered < hi - lo && mono() < deadline) {
        pollfd p{fd, POLLIN, 0};
        if (poll(&p, 1, 50) <= 0) continue;
        ssize_t n = recv(fd, buf, sizeof buf, 0);
        if (n <= 0) continue;
        each_message(buf, size_t(n), [&](int type, uint32_t mseq, size_t s, size_t e) {
            if (type != NLMSG_ERROR || e - s < 4 || mseq < lo || mseq >= hi) return;
            ++answered;
            int code = error_code(buf, s);
            if (code && failure.empty()) failure = strerror(code);
        });
    }
    if (failure.empty() && answered < hi - lo) failure = "no answer from the kernel";
    if (!failure.empty()) throw KernelError(what + ": " + failure);
}

// Add, then delete, table aodv: replaces a table left behind, and is no error without one.
void replace_table(std::vector<Msg>& out) {
    for (int msg : {NFT_MSG_NEWTABLE, NFT_MSG_DELTABLE}) {
        out.push_back(nft_message(msg, msg == NFT_MSG_NEWTABLE ? NLM_F_CREATE | NLM_F_ACK
                                                               : NLM_F_ACK, 0));
        out.back().str(NFTA_TABLE_NAME, gen::NFT_TABLE);
    }
}
}  // namespace

UseMonitor::UseMonitor(int fd, const std::string& ifname, Addr net, int plen, double period) {
    long ms = std::max(1L, long(period * 1000));
    std::vector<Msg> m;
    replace_table(m);
    m.push_back(nft_message(NFT_MSG_NEWTABLE, NLM_F_CREATE | NLM_F_ACK, 0));
    m.back().str(NFTA_TABLE_NAME, gen::NFT_TABLE);
    // set used { type ipv4_addr; flags dynamic,timeout; timeout <ms>ms; }
    m.push_back(nft_message(NFT_MSG_NEWSET, NLM_F_CREATE | NLM_F_ACK, 0));
    m.back().str(NFTA_SET_TABLE, gen::NFT_TABLE);
    m.back().str(NFTA_SET_NAME, "used");
    m.back().be32(NFTA_SET_FLAGS, NFT_SET_TIMEOUT | NFT_SET_EVAL);
    m.back().be32(NFTA_SET_KEY_TYPE, TYPE_IPADDR);
    m.back().be32(NFTA_SET_KEY_LEN, 4);
    m.back().be32(NFTA_SET_ID, SET_ID);
    m.back().be64(NFTA_SET_TIMEOUT, uint64_t(ms));
    // chain NAME { type filter hook HOOK priority 0; policy accept; }
    struct {
        const char* name;
        uint32_t hook;
    } chains[] = {{"use_forward", NF_INET_FORWARD},
                  {"use_output", NF_INET_LOCAL_OUT},
                  {"use_input", NF_INET_LOCAL_IN}};
    for (auto& c : chains) {
        m.push_back(nft_message(NFT_MSG_NEWCHAIN, NLM_F_CREATE | NLM_F_ACK, 0));
        Msg& x = m.back();
        x.str(NFTA_CHAIN_TABLE, gen::NFT_TABLE);
        x.str(NFTA_CHAIN_NAME, c.name);
        size_t h = x.begin(NFTA_CHAIN_HOOK);
        x.be32(NFTA_HOOK_HOOKNUM, c.hook);
        x.be32(NFTA_HOOK_PRIORITY, 0);
        x.end(h);
        x.be32(NFTA_CHAIN_POLICY, NF_ACCEPT);
        x.str(NFTA_CHAIN_TYPE, "filter");
    }
    char name[IFNAMSIZ] = {};
    strncpy(name, ifname.c_str(), IFNAMSIZ - 1);
    uint8_t udp = IPPROTO_UDP;
    uint16_t port = htons(uint16_t(gen::AODV_PORT));
    constexpr uint32_t SADDR = 12, DADDR = 16;
    // (chain, the interface's meta key or 0, the address's offset, the port rule first)
    struct {
        const char* chain;
        uint32_t ifkey;
        uint32_t addr;
    } rules[] = {{"use_forward", 0, DADDR},
                 {"use_forward", 0, SADDR},
                 {"use_output", NFT_META_OIFNAME, 0},  // oifname IF udp dport 654 return
                 {"use_output", NFT_META_OIFNAME, DADDR},
                 {"use_input", NFT_META_IIFNAME, 0},
                 {"use_input", NFT_META_IIFNAME, SADDR}};
    for (auto& r : rules) {
        m.push_back(nft_message(NFT_MSG_NEWRULE, NLM_F_CREATE | NLM_F_APPEND | NLM_F_ACK, 0));
        Msg& x = m.back();
        x.str(NFTA_RULE_TABLE, gen::NFT_TABLE);
        x.str(NFTA_RULE_CHAIN, r.chain);
        Rule rule(x);
        if (r.ifkey) {
            rule.meta(r.ifkey);
            rule.cmp_eq(name, IFNAMSIZ);
        }
        if (r.addr == 0) {
            rule.meta(NFT_META_L4PROTO);
            rule.cmp_eq(&udp, 1);
            rule.payload(NFT_PAYLOAD_TRANSPORT_HEADER, 2, 2);
            rule.cmp_eq(&port, 2);
            rule.ret();
        } else {
            rule.in_net(r.addr, net, plen);
            rule.payload(NFT_PAYLOAD_NETWORK_HEADER, r.addr, 4);
            rule.update_used();
        }
    }
    nft_batch(fd, m, "nftables table " + std::string(gen::NFT_TABLE));
}

void UseMonitor::remove(int fd) {
    std::vector<Msg> m;
    replace_table(m);
    nft_batch(fd, m, "remove nftables table " + std::string(gen::NFT_TABLE));
}

// -- SetReader -------------------------------------------------------------------------------
SetReader::SetReader() : fd_(netlink_socket(NETLINK_NETFILTER)) {}
SetReader::~SetReader() { close(); }

void SetReader::close() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
}

void SetReader::request() {
    ++seq_;
    found_.clear();
    Msg m((NFNL_SUBSYS_NFTABLES << 8) | NFT_MSG_GETSETELEM, NLM_F_REQUEST | NLM_F_DUMP, seq_);
    nfgenmsg g{};
    g.nfgen_family = AF_INET;
    m.put(&g, sizeof g);
    m.str(NFTA_SET_ELEM_LIST_TABLE, gen::NFT_TABLE);
    m.str(NFTA_SET_ELEM_LIST_SET, "used");
    auto& b = m.done();
    if (::send(fd_, b.data(), b.size(), 0) < 0)
        throw KernelError(std::string("route-use poll: ") + strerror(errno));
    busy = true;
}

bool SetReader::receive(std::vector<Addr>& found) {
    for (;;) {
        ssize_t n = recv(fd_, buf_.get(), BUF, 0);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) return false;
        const uint8_t* p = buf_.get();
        bool done = false;
        int code = 0;
        each_message(p, size_t(n), [&](int type, uint32_t seq, size_t s, size_t e) {
            if (done || seq != seq_) return;
            if (type == NLMSG_DONE || type == NLMSG_ERROR) {
                done = true;
                if (type == NLMSG_ERROR && e - s >= 4) code = error_code(p, s);
                return;
            }
            if (type != ((NFNL_SUBSYS_NFTABLES << 8) | NFT_MSG_NEWSETELEM)) return;
            attrs(p, s + sizeof(nfgenmsg), e, [&](int k, size_t s1, size_t e1) {
                if (k != NFTA_SET_ELEM_LIST_ELEMENTS) return;
                attrs(p, s1, e1, [&](int ek, size_t s2, size_t e2) {
                    if (ek != NFTA_LIST_ELEM) return;
                    attrs(p, s2, e2, [&](int kk, size_t s3, size_t e3) {
                        if (kk != NFTA_SET_ELEM_KEY) return;
                        attrs(p, s3, e3, [&](int dk, size_t vs, size_t ve) {
                            if (dk == NFTA_DATA_VALUE && ve - vs == 4) {
                                uint32_t a;
                                memcpy(&a, p + vs, 4);
                                found_.push_back(ntohl(a));
                            }
                        });
                    });
                });
            });
        });
        if (done) {
            busy = false;
            if (code) throw KernelError("nftables set read: " + err_text(code));
            found.swap(found_);
            found_.clear();
            return true;
        }
    }
}

// -- ICMP ------------------------------------------------------------------------------------
std::string icmp_host_unreachable(Addr own, const std::string& original) {
    const uint8_t* o = reinterpret_cast<const uint8_t*>(original.data());
    size_t ihl = size_t(o[0] & 0x0F) * 4;
    size_t q = std::min(original.size(), ihl + 8);
    std::vector<uint8_t> icmp = {3, 1, 0, 0, 0, 0, 0, 0};
    icmp.insert(icmp.end(), o, o + q);
    uint16_t c = checksum(icmp.data(), icmp.size());
    icmp[2] = uint8_t(c >> 8);
    icmp[3] = uint8_t(c);
    size_t total = 20 + icmp.size();
    uint8_t h[20] = {0x45, 0, uint8_t(total >> 8), uint8_t(total), 0, 0, 0, 0, 64, IPPROTO_ICMP};
    uint32_t src = htonl(own);
    memcpy(h + 12, &src, 4);
    memcpy(h + 16, o + 12, 4);
    c = checksum(h, 20);
    h[10] = uint8_t(c >> 8);
    h[11] = uint8_t(c);
    std::string out(reinterpret_cast<const char*>(h), 20);
    out.append(reinterpret_cast<const char*>(icmp.data()), icmp.size());
    return out;
}

bool quoted_datagram(const uint8_t* p, size_t n, Addr own, int& udp_len, std::string& payload) {
    if (n < 1) return false;
    size_t outer = size_t(p[0] & 0x0F) * 4;
    if (outer >= n || p[outer] != 3) return false;
    size_t inner = outer + 8;
    if (inner + 16 > n) return false;
    size_t ihl = size_t(p[inner] & 0x0F) * 4;
    if (p[inner + 9] != IPPROTO_UDP) return false;
    uint32_t src;
    memcpy(&src, p + inner + 12, 4);
    if (ntohl(src) != own) return false;
    size_t u = inner + ihl;
    if (u + 6 > n) return false;
    int sport = p[u] << 8 | p[u + 1], dport = p[u + 2] << 8 | p[u + 3];
    int length = p[u + 4] << 8 | p[u + 5];
    if (sport != gen::AODV_PORT || dport != gen::AODV_PORT || length < 8) return false;
    size_t start = std::min(n, u + 8), end = std::min(n, u + size_t(length));
    udp_len = length;
    payload.assign(reinterpret_cast<const char*>(p) + start, end > start ? end - start : 0);
    return true;
}

}  // namespace aodv
