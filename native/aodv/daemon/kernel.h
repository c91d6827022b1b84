// Kernel objects the compiled AODV daemon owns inside its robot's namespace (the twin of
// aodv/kernel.py; read its docstring for the why of each):
//
// - `KernelRoutes`: /32 routes of protocol RTPROT_AODV over a raw NETLINK_ROUTE socket, the
//   messages laid out as topology/kernel/netlinkmsg.py lays them out. At run time installs
//   and deletes ask for no acknowledgement (the kernel answers only a failure, which the loop
//   reads with read_acks); start-up and teardown requests ask and wait (up to 5 s).
// - `Tun`: the TUN device (no packet info) that catches packets with no route.
// - `UseMonitor`: the nftables table whose dynamic set collects the addresses data packets
//   crossed; made and removed with one nftables batch over NETLINK_NETFILTER each (start and
//   teardown only; no `nft` forked), the Python daemon's ruleset as nft compiles it.
// - `SetReader`: reads that set over NETLINK_NETFILTER without blocking, no `nft` forked.
//
// Every failure is a KernelError whose what() is the one line the daemon prints.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "../packet.h"

namespace aodv {

struct KernelError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

void write_sysctl(const std::string& path, const std::string& value);
int ifindex(const std::string& name);
Addr ipv4_address(const std::string& name);
void set_up(const std::string& name);
// The classic BPF program dropping datagrams whose IP source is `own` (aodv.kernel).
void drop_own_datagrams(int fd, Addr own);

class KernelRoutes {
  public:
    explicit KernelRoutes(const std::string& ifname);
    ~KernelRoutes();
    KernelRoutes(const KernelRoutes&) = delete;
    KernelRoutes& operator=(const KernelRoutes&) = delete;

    int fd() const { return nl_; }
    Addr address() const { return ipv4_address(ifname_); }
    // (destination, prefix length) of the routes with our protocol number, any table.
    std::vector<std::pair<Addr, int>> ours();
    // Delete every route with our protocol number; how many there were.
    size_t flush();
    // `ip route replace DEST/32 [via NEXT onlink] dev IFACE proto RTPROT_AODV`.
    uint32_t install(Addr dest, Addr next_hop, bool ack = false);
    uint32_t remove(Addr dest, int plen = 32, bool ack = false);
    // NET dev TUN src SRC metric 1000 proto RTPROT_AODV (waits for the kernel's answer).
    void catch_all(int oif, Addr net, int plen, Addr src);
    // The kernel's answers that arrived: one line per refused request.
    std::vector<std::string> read_acks();
    void close();

  private:
    uint32_t next_seq(const std::string& what);
    void send(const std::vector<uint8_t>& msg, const std::string& what);
    std::string ack(uint32_t seq, int code);  // the failure, or "" for an acknowledgement
    void wait(uint32_t seq);
    // Every message readable within `timeout_ms` (0: now): (type, seq, payload).
    template <class F>
    void messages(int timeout_ms, F&& each);

    // Answers are read on one thread at a time (start-up, then the loop, then teardown) into
    // this buffer, not zeroed: its pages are resident only once answers used them.
    static constexpr size_t BUF = 1 << 16;
    std::unique_ptr<uint8_t[]> buf_{new uint8_t[BUF]};
    std::string ifname_;
    int ifindex_;
    int nl_ = -1;
    uint32_t seq_ = 0;
    // What each recent request was (the newest PENDING_MAX), to name the one an error is
    // about: sent by the kernel thread, answered on the loop's.
    std::mutex pending_mu_;
    std::map<uint32_t, std::string> pending_;
};

class Tun {
  public:
    explicit Tun(const std::string& name);
    ~Tun();
    Tun(const Tun&) = delete;
    Tun& operator=(const Tun&) = delete;
    int fd() const { return fd_; }
    int ifindex() const { return ifindex_; }
    // One packet into `buf`; its length, 0 when none waits.
    ssize_t read(uint8_t* buf, size_t n);
    bool write(const std::string& packet);
    void close();

  private:
    int fd_ = -1;
    int ifindex_ = 0;
};

class UseMonitor {
  public:
    // The table for data on `ifname` to and from net/plen (host order), its set's entries
    // living `period` seconds; a table of that name left behind is replaced. `fd`: a
    // NETLINK_NETFILTER socket (the SetReader's) to send the batch over.
    UseMonitor(int fd, const std::string& ifname, Addr net, int plen, double period);
    static void remove(int fd);
};

class SetReader {
  public:
    SetReader();
    ~SetReader();
    SetReader(const SetReader&) = delete;
    SetReader& operator=(const SetReader&) = delete;
    int fd() const { return fd_; }
    void request();
    // true when the dump is complete (`found` holds the addresses); false before.
    bool receive(std::vector<Addr>& found);
    void close();
    bool busy = false;

  private:
    static constexpr size_t BUF = 1 << 16;
    std::unique_ptr<uint8_t[]> buf_{new uint8_t[BUF]};  // read by the loop alone
    int fd_ = -1;
    uint32_t seq_ = 0;
    std::vector<Addr> found_;
};

// ICMP (aodv/icmp.py): a destination unreachable (type 3, code 1) about `original` to its
// sender, from `own`; and the AODV datagram an ICMP destination unreachable quotes, if `own`
// sent it (UDP 654 to 654): its UDP length and the quoted payload.
std::string icmp_host_unreachable(Addr own, const std::string& original);
bool quoted_datagram(const uint8_t* p, size_t n, Addr own, int& udp_len, std::string& payload);

}  // namespace aodv
