// tb-ns3-wifi: an 802.11 channel between the robots of one testbed, simulated by ns-3 in
// real time and carrying the robots' real Ethernet frames.
//
// Theory of operation. The process runs in the testbed's medium namespace (tb-NAME-m), where
// robot K's wlan0 has its veth peer rpK (no bridges). Per robot there is one ns-3 ghost node
// with two devices:
//
//   rpK  <-AF_PACKET->  FdNetDevice  --relay-->  WifiNetDevice (ad hoc)  <-- YansWifiChannel
//
// Linux to air: every frame the robot sends arrives on rpK, is read by the FdNetDevice (its
// promiscuous callback: the destination is some other robot's MAC) and, if its source is the
// robot's own MAC, is handed to WifiNetDevice::Send with its destination and EtherType. The
// WiFi MAC queues it, contends for the channel (DCF), sends it and retries it until acked.
// Air to Linux: what the WiFi MAC accepts (addressed to this robot, or group-addressed) comes
// out of its forward-up callback; the LLC/SNAP header gives the EtherType and
// FdNetDevice::SendFrom writes the frame, with the sender's MAC as source, into rpK, whence
// it reaches wlan0. Each wlan0 carries the MAC of its robot's WifiNetDevice, so nothing is
// rewritten and ARP, IPv6 neighbour discovery and batman's Ethernet frames simply work.
//
// The channel's propagation is a cut-off at the communication range (RangePropagationLoss:
// the veth medium's disc) or log-distance calibrated so that the weakest rate is still heard
// at the range. Positions come from the controller over a Unix stream socket, one text line
// per request (see the protocol below); a control thread reads them and schedules the change
// into the simulator, which is thread-safe for that (ScheduleWithContext), then answers once
// the change is applied.
//
// Time: the real-time simulator paces events against a synchronizer. The stock one runs at
// the wall clock's speed; ScaledSynchronizer below runs K times faster (the testbed's time
// scale): one emulated second is 1/K s of wall time, so the channel's airtime and back-offs
// shrink by K with everything else in the run. A periodic probe records how late the
// simulator runs behind that clock, and every relayed frame how late it was handled (the
// medium's own fidelity); with --rt-priority the process asks for SCHED_RR, like the
// testbed's world loop. With --lag-file, each frame delivered to a robot leaves a record of
// its relay lag, the wall time its two relays added beyond its emulated time on the channel
// (LagRecord below), which the analysis takes out of the delays it measures.
//
// Usage: tb-ns3-wifi --socket PATH --range M [--loss range|logdistance]
//          [--standard 80211a|80211b|80211g] [--rate WIFIMODE|minstrel] [--time-scale K]
//          [--rt-priority N] [--lag-file PATH [--lag-cap-bytes N]]
//          --robot IFNAME,MAC,X,Y ...   (one --robot per robot, in order)
// Bad arguments: one line on stderr, exit 2. It runs until SIGTERM.
//
// Protocol (requests and answers are single lines of ASCII):
//   pos X1 Y1 X2 Y2 ...   -> "ok"             every robot's position, metres
//   stats                 -> one JSON object  counters per robot, timer lateness, relay lag
//   links                 -> "links 1-2 2-3"  the pairs that hear each other (1-based), by
//                                              the propagation model at the current positions
//   ping                  -> "ok"             answered from inside the simulator (readiness)
//   flush                 -> "ok"             the lag records so far are in the file (stats
//                                              flushes them too)
// Anything else is answered "error ..." and the connection stays open.

#include <ns3/core-module.h>
#include <ns3/fd-net-device-module.h>
#include <ns3/mobility-module.h>
#include <ns3/network-module.h>
#include <ns3/propagation-module.h>
#include <ns3/realtime-simulator-impl.h>
#include <ns3/wifi-module.h>

#include <arpa/inet.h>
#include <sched.h>
#include <sys/prctl.h>
#include <time.h>
#include <sys/resource.h>
#include <linux/if_packet.h>
#include <net/ethernet.h>
#include <net/if.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cctype>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <future>
#include <map>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

using namespace ns3;

namespace
{

[[noreturn]] void
Fail(const std::string& what)
{
    std::fprintf(stderr, "tb-ns3-wifi: %s\n", what.c_str());
    std::exit(2);
}

// ---- a synchronizer K times faster than the wall clock -------------------------------------

class ScaledSynchronizer : public Synchronizer
{
  public:
    explicit ScaledSynchronizer(double scale)
        : m_scale(scale)
    {
    }

  private:
    using Clock = std::chrono::steady_clock;

    uint64_t Wall() const
    {
        return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - m_origin)
            .count();
    }

    void DoSetOrigin(uint64_t) override
    {
        m_origin = Clock::now();
    }

    bool DoRealtime() override
    {
        return true;
    }

    uint64_t DoGetCurrentRealtime() override
    {
        return static_cast<uint64_t>(Wall() * m_scale);
    }

    // Wait until the emulated clock reaches nsCurrent + nsDelay; false if signalled first.
    bool DoSynchronize(uint64_t nsCurrent, uint64_t nsDelay) override
    {
        const uint64_t target = nsCurrent + nsDelay;
        std::unique_lock<std::mutex> lock(m_mutex);
        while (true)
        {
            const uint64_t now = DoGetCurrentRealtime();
            if (now >= target)
            {
                return true;
            }
            auto wall = std::chrono::nanoseconds(static_cast<int64_t>((target - now) / m_scale));
            if (m_cond.wait_for(lock, wall, [this] { return m_condition; }))
            {
                return false;
            }
        }
    }

    void DoSignal() override
    {
        std::lock_guard<std::mutex> lock(m_mutex);
        m_condition = true;
        m_cond.notify_all();
    }

    void DoSetCondition(bool cond) override
    {
        std::lock_guard<std::mutex> lock(m_mutex);
        m_condition = cond;
    }

    int64_t DoGetDrift(uint64_t ns) override
    {
        return static_cast<int64_t>(DoGetCurrentRealtime()) - static_cast<int64_t>(ns);
    }

    void DoEventStart() override
    {
        m_eventStart = DoGetCurrentRealtime();
    }

    uint64_t DoEventEnd() override
    {
        return DoGetCurrentRealtime() - m_eventStart;
    }

    double m_scale;
    Clock::time_point m_origin{Clock::now()};
    uint64_t m_eventStart{0};
    std::mutex m_mutex;
    std::condition_variable m_cond;
    bool m_condition{false};
};

// RealtimeSimulatorImpl creates its WallClockSynchronizer itself and has no setter. Explicit
// instantiation may name a private member (C++ [temp.explicit]): that gives its address.
struct SyncMember
{
    using type = Ptr<Synchronizer> RealtimeSimulatorImpl::*;
    friend type Get(SyncMember);
};

template <typename Tag, typename Tag::type M>
struct Expose
{
    friend typename Tag::type Get(Tag)
    {
        return M;
    }
};

template struct Expose<SyncMember, &RealtimeSimulatorImpl::m_synchronizer>;

// ---- options ---------------------------------------------------------------------------------

struct Robot
{
    std::string ifname;
    Mac48Address mac;
    double x{0};
    double y{0};
};

struct Options
{
    std::string socketPath;
    double range{0};
    std::string loss{"range"};     // range | logdistance
    std::string standard{"80211a"}; // 80211a | 80211b | 80211g
    std::string rate;               // a WifiMode name, or "minstrel"
    double timeScale{1.0};
    int rtPriority{0}; // SCHED_RR priority of the simulator (0: normal scheduling)
    std::string lagFile;   // per-frame relay lag records (empty: none)
    uint64_t lagCapBytes{32u << 20};
    std::vector<Robot> robots;
};

double
Number(const std::string& what, const std::string& text)
{
    char* end = nullptr;
    double v = std::strtod(text.c_str(), &end);
    if (text.empty() || *end != '\0' || !std::isfinite(v))
    {
        Fail(what + " must be a number, not '" + text + "'");
    }
    return v;
}

// --robot IFNAME,MAC,X,Y (once per robot, in robot order)
Robot
ParseRobot(const std::string& arg)
{
    std::vector<std::string> parts;
    std::stringstream ss(arg);
    std::string item;
    while (std::getline(ss, item, ','))
    {
        parts.push_back(item);
    }
    if (parts.size() != 4)
    {
        Fail("--robot wants IFNAME,MAC,X,Y, not '" + arg + "'");
    }
    Robot r;
    r.ifname = parts[0];
    bool macOk = parts[1].size() == 17;
    for (size_t i = 0; macOk && i < 17; ++i)
        macOk = (i % 3 == 2) ? parts[1][i] == ':' : std::isxdigit(parts[1][i]) != 0;
    if (!macOk)
        Fail("bad MAC address '" + parts[1] + "'");
    r.mac = Mac48Address(parts[1].c_str());
    r.x = Number("x", parts[2]);
    r.y = Number("y", parts[3]);
    return r;
}

Options
ParseArgs(int argc, char** argv)
{
    Options o;
    for (int i = 1; i < argc; ++i)
    {
        std::string key = argv[i];
        if (i + 1 >= argc)
        {
            Fail(key + " needs a value");
        }
        std::string value = argv[++i];
        if (key == "--socket")
            o.socketPath = value;
        else if (key == "--range")
            o.range = Number("--range", value);
        else if (key == "--loss")
            o.loss = value;
        else if (key == "--standard")
            o.standard = value;
        else if (key == "--rate")
            o.rate = value;
        else if (key == "--time-scale")
            o.timeScale = Number("--time-scale", value);
        else if (key == "--rt-priority")
            o.rtPriority = static_cast<int>(Number("--rt-priority", value));
        else if (key == "--lag-file")
            o.lagFile = value;
        else if (key == "--lag-cap-bytes")
        {
            double cap = Number("--lag-cap-bytes", value);
            if (cap < 0 || cap > 1e15)
                Fail("--lag-cap-bytes must be between 0 and 1e15");
            o.lagCapBytes = static_cast<uint64_t>(cap);
        }
        else if (key == "--robot")
            o.robots.push_back(ParseRobot(value));
        else
            Fail("unknown option " + key);
    }
    if (o.socketPath.empty() || o.robots.empty())
        Fail("usage: tb-ns3-wifi --socket PATH --range M --robot IFNAME,MAC,X,Y ...");
    if (!(o.range > 0))
        Fail("--range must be > 0");
    if (!(o.timeScale > 0))
        Fail("--time-scale must be > 0");
    if (o.loss != "range" && o.loss != "logdistance")
        Fail("--loss is range or logdistance, not " + o.loss);
    if (o.standard != "80211a" && o.standard != "80211b" && o.standard != "80211g")
        Fail("--standard is 80211a, 80211b or 80211g, not " + o.standard);
    return o;
}

// ---- the ghost nodes and their counters -------------------------------------------------------

struct Counters
{
    uint64_t fromLinux{0};    // frames the robot sent, handed to the WiFi MAC
    uint64_t toLinux{0};      // frames the WiFi MAC delivered, written to the robot
    uint64_t foreign{0};      // frames on rpK whose source was not the robot (ignored)
    uint64_t macTx{0};        // MSDUs the MAC accepted for sending
    uint64_t retries{0};      // data transmissions that were not acknowledged
    uint64_t retryDrops{0};   // MSDUs given up after the retry limit
    uint64_t macTxDrops{0};   // MSDUs the MAC dropped before transmission
    uint64_t enqueued{0};     // MPDUs that entered the MAC's queue
    uint64_t queueExpired{0}; // MPDUs that waited in it longer than its MaxDelay
    uint64_t phyTxDrops{0};
    uint64_t phyRxDrops{0};
    std::map<std::string, uint64_t> phyRxDropReasons;
    int64_t airtimeNs{0};     // time the PHY spent transmitting
};

struct Ghost
{
    Robot robot;
    Ptr<Node> node;
    Ptr<FdNetDevice> fd;
    Ptr<WifiNetDevice> wifi;
    Ptr<MobilityModel> mobility;
    std::vector<Ptr<WifiMacQueue>> queues; // the MAC's transmit queues (one without QoS)
    Counters c;
};

std::vector<Ghost> g_ghosts;
Ptr<PropagationLossModel> g_loss; // the channel's, to answer "links"

// How far behind the emulated clock the simulator runs when it executes an event.
struct Lag
{
    uint64_t count{0};
    int64_t maxNs{0};
    double sumNs{0};
    uint64_t over1ms{0};

    void Add()
    {
        auto impl = DynamicCast<RealtimeSimulatorImpl>(Simulator::GetImplementation());
        int64_t late = (impl->RealtimeNow() - Simulator::Now()).GetNanoSeconds();
        late = std::max<int64_t>(late, 0);
        count++;
        sumNs += late;
        maxNs = std::max(maxNs, late);
        if (late > 1000000)
            over1ms++;
    }

    std::string Json(const char* countName) const
    {
        std::ostringstream s;
        s << "{\"" << countName << "\": " << count << ", \"max_ms\": " << maxNs / 1e6
          << ", \"mean_ms\": " << (count ? sumNs / count / 1e6 : 0.0)
          << ", \"over_1ms\": " << over1ms << "}";
        return s.str();
    }
};

Lag g_late;  // a probe every kProbeEvery: timer lateness
Lag g_relay; // each frame relayed: from its scheduled time (arrival, end of reception) to now

const Time kProbeEvery = MilliSeconds(10);

void
LatenessProbe()
{
    g_late.Add();
    Simulator::Schedule(kProbeEvery, &LatenessProbe);
}

// ---- each frame's relay lag -------------------------------------------------------------------
//
// What the relay adds to a frame's trip from one robot's wlan0 to another's, beyond the
// channel's emulated time (airtime, contention, back-off, retries), in wall-clock ns:
//   in:  from the frame's arrival on rpK (the kernel's receive stamp, SO_TIMESTAMPNS) to the
//        emulated instant at which it entered the WiFi MAC (the time its relay event was
//        scheduled for), i.e. the reader thread's wake-up and the hand-over;
//   out: from the emulated instant its reception ended (the forward-up event's time) to the
//        moment it was written into rpJ.
// A relay event the simulator handles late delays the frame's entry into the MAC only in
// wall time, not in emulated time: the MAC's next events are then already due and run at
// once, and whatever lateness is left when the reception ends is in `out`. So in + out is
// exactly the frame's wall time on the relay minus its emulated time on the channel / K.

int64_t
RealtimeNs()
{
    timespec ts{};
    clock_gettime(CLOCK_REALTIME, &ts);
    return static_cast<int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
}

double g_timeScale = 1.0;

// Wall-clock ns since the emulated instant `at` (now by the simulator's scaled clock).
int64_t
WallSince(Time at)
{
    auto impl = DynamicCast<RealtimeSimulatorImpl>(Simulator::GetImplementation());
    return static_cast<int64_t>((impl->RealtimeNow() - at).GetNanoSeconds() / g_timeScale);
}

// Carried by a frame from its sender's ghost through the MAC (retries included) and the
// channel to each receiver's forward-up: who sent it and its lag on the way in.
class RelayTag : public Tag
{
  public:
    uint16_t sender{0}; // robot number, 1-based
    int64_t inNs{0};

    static TypeId GetTypeId()
    {
        static TypeId tid =
            TypeId("tb::RelayTag").SetParent<Tag>().AddConstructor<RelayTag>();
        return tid;
    }

    TypeId GetInstanceTypeId() const override
    {
        return GetTypeId();
    }

    uint32_t GetSerializedSize() const override
    {
        return 10;
    }

    void Serialize(TagBuffer b) const override
    {
        b.WriteU16(sender);
        b.WriteU64(static_cast<uint64_t>(inNs));
    }

    void Deserialize(TagBuffer b) override
    {
        sender = b.ReadU16();
        inNs = static_cast<int64_t>(b.ReadU64());
    }

    void Print(std::ostream& os) const override
    {
        os << "sender=" << sender << " in_ns=" << inNs;
    }
};

// The file of per-frame records, one per frame delivered to a robot: "TBRLAG01", then
// 40-byte little-endian records (topology/radio/ns3wifi.py and testbed/analysis/relaylag.py read
// them; docs/ns3-medium.md, "Each frame's relay lag"). A cap on its size: records past it
// are counted, not written.
#pragma pack(push, 1)
struct LagRecord
{
    uint64_t writtenNs; // CLOCK_REALTIME when the frame had been written into rpJ
    uint32_t inNs;      // lag on the way in (saturated at 2^32-1; never negative)
    uint32_t outNs;     // lag on the way out
    uint16_t receiver;  // robot J, 1-based
    uint16_t sender;    // robot K whose rpK the frame came from (0: unknown)
    uint16_t etherType;
    uint16_t ipId;      // IPv4 only (else 0), like the fields below
    uint8_t ipSrc[4];   // network order
    uint8_t ipDst[4];
    uint32_t tcpSeq;    // TCP only: the raw sequence number
    uint8_t ipProto;
    uint8_t tcpFlags;
    uint16_t reserved;
};
#pragma pack(pop)
static_assert(sizeof(LagRecord) == 40, "the lag file's record is 40 bytes");

struct LagLog
{
    FILE* file{nullptr};
    uint64_t capRecords{0};
    uint64_t written{0};
    uint64_t notWritten{0}; // past the cap, or a failed write
    uint64_t untagged{0};   // delivered frames without a RelayTag (should stay 0)
    uint64_t inStampMissing{0}; // arrivals without a usable kernel stamp (read time used)
    int64_t sumInNs{0};
    int64_t sumOutNs{0};

    void Open(const std::string& path, uint64_t capBytes)
    {
        file = std::fopen(path.c_str(), "wb");
        if (file == nullptr)
            Fail("lag file " + path + ": " + std::strerror(errno));
        static char buffer[1 << 16];
        std::setvbuf(file, buffer, _IOFBF, sizeof(buffer));
        static const char magic[8] = {'T', 'B', 'R', 'L', 'A', 'G', '0', '1'};
        std::fwrite(magic, 1, sizeof(magic), file);
        capRecords = capBytes > sizeof(magic) ? (capBytes - sizeof(magic)) / sizeof(LagRecord) : 0;
    }

    void Add(const LagRecord& r)
    {
        sumInNs += r.inNs;
        sumOutNs += r.outNs;
        if (file == nullptr)
            return;
        if (written >= capRecords || std::fwrite(&r, sizeof(r), 1, file) != 1)
        {
            notWritten++;
            return;
        }
        written++;
    }

    void Flush()
    {
        if (file != nullptr)
            std::fflush(file);
    }

    std::string Json() const
    {
        uint64_t n = written + notWritten;
        std::ostringstream s;
        s << "{\"records\": " << written << ", \"not_written\": " << notWritten
          << ", \"untagged\": " << untagged << ", \"in_stamp_missing\": " << inStampMissing
          << ", \"mean_in_ms\": " << (n ? sumInNs / 1e6 / n : 0.0)
          << ", \"mean_out_ms\": " << (n ? sumOutNs / 1e6 / n : 0.0) << "}";
        return s.str();
    }
};

LagLog g_lagLog;

uint32_t
Saturate(int64_t ns)
{
    return static_cast<uint32_t>(std::clamp<int64_t>(ns, 0, UINT32_MAX));
}

// The identity of an IPv4 frame's packet (fields that no hop changes), into `r`.
void
Identify(Ptr<const Packet> payload, uint16_t etherType, LagRecord& r)
{
    r.etherType = etherType;
    if (etherType != 0x0800)
        return;
    uint8_t h[80];
    uint32_t n = payload->CopyData(h, sizeof(h));
    if (n < 20 || (h[0] >> 4) != 4)
        return;
    const uint32_t ihl = (h[0] & 0x0f) * 4u;
    r.ipId = static_cast<uint16_t>(h[4] << 8 | h[5]);
    r.ipProto = h[9];
    std::memcpy(r.ipSrc, h + 12, 4);
    std::memcpy(r.ipDst, h + 16, 4);
    if (r.ipProto == 6 && ihl >= 20 && n >= ihl + 14)
    {
        const uint8_t* t = h + ihl;
        r.tcpSeq = uint32_t(t[4]) << 24 | uint32_t(t[5]) << 16 | uint32_t(t[6]) << 8 | t[7];
        r.tcpFlags = t[13];
    }
}

// Reads rpK like ns-3's FdNetDeviceFdReader, and appends to each frame the kernel's stamp of
// its arrival (8 bytes, CLOCK_REALTIME ns), which FromLinux takes off again before the frame
// goes to the MAC. The stamp rides in the buffer because FdNetDevice hands buffers from this
// thread to the simulator through a queue of its own that may drop some.
class StampingReader : public FdReader
{
    static constexpr size_t kFrameMax = 1500 + 22; // what ns-3's own reader reads (MTU 1500)

    FdReader::Data DoRead() override
    {
        auto* buf = static_cast<uint8_t*>(std::malloc(kFrameMax + sizeof(int64_t)));
        iovec iov{buf, kFrameMax};
        alignas(cmsghdr) char control[CMSG_SPACE(sizeof(timespec))];
        msghdr msg{};
        msg.msg_iov = &iov;
        msg.msg_iovlen = 1;
        msg.msg_control = control;
        msg.msg_controllen = sizeof(control);
        ssize_t len = recvmsg(m_fd, &msg, 0);
        if (len <= 0)
        {
            std::free(buf);
            return FdReader::Data(nullptr, 0);
        }
        const int64_t now = RealtimeNs();
        int64_t stamp = 0;
        for (cmsghdr* c = CMSG_FIRSTHDR(&msg); c != nullptr; c = CMSG_NXTHDR(&msg, c))
        {
            if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SCM_TIMESTAMPNS)
            {
                timespec ts;
                std::memcpy(&ts, CMSG_DATA(c), sizeof(ts));
                stamp = static_cast<int64_t>(ts.tv_sec) * 1000000000 + ts.tv_nsec;
            }
        }
        // A stamp from another clock or none at all: the read's own time (counted).
        if (stamp <= 0 || stamp > now || now - stamp > 1000000000)
            stamp = -now;
        std::memcpy(buf + len, &stamp, sizeof(stamp));
        return FdReader::Data(buf, len + static_cast<ssize_t>(sizeof(stamp)));
    }
};

class StampingFdNetDevice : public FdNetDevice
{
    Ptr<FdReader> DoCreateFdReader() override
    {
        return Create<StampingReader>();
    }
};

int
OpenPacketSocket(const std::string& ifname)
{
    int fd = socket(AF_PACKET, SOCK_RAW, htons(ETH_P_ALL));
    if (fd < 0)
        Fail("AF_PACKET socket: " + std::string(std::strerror(errno)) + " (needs root)");
    unsigned index = if_nametoindex(ifname.c_str());
    if (index == 0)
        Fail("no interface " + ifname + " in this namespace");
    sockaddr_ll sll{};
    sll.sll_family = AF_PACKET;
    sll.sll_protocol = htons(ETH_P_ALL);
    sll.sll_ifindex = static_cast<int>(index);
    if (bind(fd, reinterpret_cast<sockaddr*>(&sll), sizeof(sll)) < 0)
        Fail("bind to " + ifname + ": " + std::strerror(errno));
    // What we write into rpK must not come back to us as if the robot had sent it.
    int one = 1;
#ifndef PACKET_IGNORE_OUTGOING
#define PACKET_IGNORE_OUTGOING 23
#endif
    if (setsockopt(fd, SOL_PACKET, PACKET_IGNORE_OUTGOING, &one, sizeof(one)) < 0)
        Fail("PACKET_IGNORE_OUTGOING: " + std::string(std::strerror(errno)));
    // Each frame's arrival time, for its relay lag (StampingReader).
    if (setsockopt(fd, SOL_SOCKET, SO_TIMESTAMPNS, &one, sizeof(one)) < 0)
        Fail("SO_TIMESTAMPNS: " + std::string(std::strerror(errno)));
    return fd;
}

template <typename T, typename Cb>
void
Trace(Ptr<T> object, const char* source, Cb callback)
{
    if (!object->TraceConnectWithoutContext(source, callback))
        Fail(std::string("no trace source ") + source);
}

// Linux to air.
bool
FromLinux(size_t k,
          Ptr<NetDevice>,
          Ptr<const Packet> packet,
          uint16_t protocol,
          const Address& from,
          const Address& to,
          NetDevice::PacketType)
{
    Ghost& g = g_ghosts[k];
    // StampingReader's arrival stamp, at the end (negative: the read's time, no kernel stamp).
    Ptr<Packet> frame = packet->Copy();
    int64_t stamp = 0;
    if (frame->GetSize() < sizeof(stamp))
        return true;
    frame->CreateFragment(frame->GetSize() - sizeof(stamp), sizeof(stamp))
        ->CopyData(reinterpret_cast<uint8_t*>(&stamp), sizeof(stamp));
    frame->RemoveAtEnd(sizeof(stamp));
    if (Mac48Address::ConvertFrom(from) != g.robot.mac)
    {
        g.c.foreign++;
        return true;
    }
    if (stamp < 0)
    {
        g_lagLog.inStampMissing++;
        stamp = -stamp;
    }
    g.c.fromLinux++;
    g_relay.Add();
    RelayTag tag;
    tag.sender = static_cast<uint16_t>(k + 1);
    // Wall time since the arrival, less the wall time since the emulated instant the frame
    // enters the MAC at (now, by the simulator's clock).
    tag.inNs = std::max<int64_t>(0, (RealtimeNs() - stamp) - WallSince(Simulator::Now()));
    frame->AddPacketTag(tag);
    g.wifi->Send(frame, to, protocol);
    return true;
}

bool
Ignore(Ptr<NetDevice>, Ptr<const Packet>, uint16_t, const Address&)
{
    return true;
}

// Air to Linux.
void
ToLinux(size_t k, Ptr<const Packet> packet, Mac48Address from, Mac48Address to)
{
    Ghost& g = g_ghosts[k];
    Ptr<Packet> copy = packet->Copy();
    LlcSnapHeader llc;
    copy->RemoveHeader(llc);
    g.c.toLinux++;
    g_relay.Add();
    RelayTag tag;
    const bool tagged = copy->RemovePacketTag(tag);
    LagRecord r{};
    Identify(copy, llc.GetType(), r);
    // Stamped as the write begins: the write itself carries the frame through rpJ into the
    // robot's wlan0 (where its capture stamps it) and on, when the robot answers at once,
    // through its whole stack; that is not the relay's.
    r.outNs = Saturate(WallSince(Simulator::Now()));
    r.writtenNs = static_cast<uint64_t>(RealtimeNs());
    g.fd->SendFrom(copy, from, to, llc.GetType());
    r.receiver = static_cast<uint16_t>(k + 1);
    if (tagged)
    {
        r.sender = tag.sender;
        r.inNs = Saturate(tag.inNs);
    }
    else
        g_lagLog.untagged++;
    g_lagLog.Add(r);
}

void
Build(const Options& o)
{
    const size_t n = o.robots.size();
    NodeContainer nodes;
    nodes.Create(n);

    WifiHelper wifi;
    std::string control;
    std::string data = o.rate;
    if (o.standard == "80211a")
    {
        wifi.SetStandard(WIFI_STANDARD_80211a);
        control = "OfdmRate6Mbps";
        if (data.empty())
            data = "OfdmRate54Mbps";
    }
    else if (o.standard == "80211g")
    {
        wifi.SetStandard(WIFI_STANDARD_80211g);
        control = "ErpOfdmRate6Mbps";
        if (data.empty())
            data = "ErpOfdmRate54Mbps";
    }
    else
    {
        wifi.SetStandard(WIFI_STANDARD_80211b);
        control = "DsssRate1Mbps";
        if (data.empty())
            data = "DsssRate11Mbps";
    }
    if (data == "minstrel")
        wifi.SetRemoteStationManager("ns3::MinstrelWifiManager");
    else
        wifi.SetRemoteStationManager("ns3::ConstantRateWifiManager",
                                     "DataMode",
                                     StringValue(data),
                                     "ControlMode",
                                     StringValue(control));

    if (o.loss == "range")
    {
        g_loss = CreateObject<RangePropagationLossModel>();
        g_loss->SetAttribute("MaxRange", DoubleValue(o.range));
    }
    else
    {
        // Exponent 3 (indoors); the reference loss puts the edge of reception (the PHY's
        // default sensitivity, -101 dBm, at the default 16.0206 dBm of transmit power) at
        // the communication range. Faster rates need more SNR and reach less far.
        const double exponent = 3.0;
        g_loss = CreateObject<LogDistancePropagationLossModel>();
        g_loss->SetAttribute("Exponent", DoubleValue(exponent));
        g_loss->SetAttribute("ReferenceLoss",
                             DoubleValue(16.0206 + 101.0 - 10 * exponent * std::log10(o.range)));
    }
    Ptr<YansWifiChannel> air = CreateObject<YansWifiChannel>();
    air->SetPropagationLossModel(g_loss);
    air->SetPropagationDelayModel(CreateObject<ConstantSpeedPropagationDelayModel>());
    YansWifiPhyHelper phy;
    phy.SetChannel(air);

    WifiMacHelper mac;
    mac.SetType("ns3::AdhocWifiMac");
    NetDeviceContainer devices = wifi.Install(phy, mac, nodes);

    MobilityHelper mobility;
    mobility.SetMobilityModel("ns3::ConstantPositionMobilityModel");
    mobility.Install(nodes);

    g_ghosts.resize(n);
    for (size_t k = 0; k < n; ++k)
    {
        Ghost& g = g_ghosts[k];
        g.robot = o.robots[k];
        g.node = nodes.Get(k);
        g.mobility = g.node->GetObject<MobilityModel>();
        g.mobility->SetPosition(Vector(g.robot.x, g.robot.y, 0));

        g.wifi = DynamicCast<WifiNetDevice>(devices.Get(k));
        g.wifi->SetAddress(g.robot.mac);
        // In 3.37 the frame exchange manager keeps the address it had at installation:
        // without this it ignores every ACK sent to the new one (and retries 7 times).
        g.wifi->GetMac()->GetFrameExchangeManager()->SetAddress(g.robot.mac);
        g.wifi->GetMac()->SetForwardUpCallback(MakeBoundCallback(&ToLinux, k));

        g.fd = CreateObject<StampingFdNetDevice>();
        g.fd->SetAddress(Mac48Address::Allocate());
        g.node->AddDevice(g.fd);
        g.fd->SetFileDescriptor(OpenPacketSocket(g.robot.ifname));
        g.fd->SetReceiveCallback(MakeCallback(&Ignore));
        g.fd->SetPromiscReceiveCallback(MakeBoundCallback(&FromLinux, k));

        Counters* c = &g.c;
        Ptr<WifiRemoteStationManager> rsm = g.wifi->GetRemoteStationManager();
        Trace(rsm, "MacTxDataFailed",
            MakeCallback(+[](Counters* c, Mac48Address) { c->retries++; }).Bind(c));
        Trace(rsm, "MacTxFinalDataFailed",
            MakeCallback(+[](Counters* c, Mac48Address) { c->retryDrops++; }).Bind(c));
        Ptr<WifiMac> wmac = g.wifi->GetMac();
        Trace(wmac, "MacTx",
            MakeCallback(+[](Counters* c, Ptr<const Packet>) { c->macTx++; }).Bind(c));
        Trace(wmac, "MacTxDrop",
            MakeCallback(+[](Counters* c, Ptr<const Packet>) { c->macTxDrops++; }).Bind(c));
        std::vector<Ptr<Txop>> txops{wmac->GetTxop()};
        if (wmac->GetQosSupported())
        {
            txops.clear();
            for (AcIndex ac : {AC_BE, AC_BK, AC_VI, AC_VO})
                txops.push_back(wmac->GetQosTxop(ac));
        }
        for (const Ptr<Txop>& txop : txops)
        {
            Ptr<WifiMacQueue> queue = txop->GetWifiMacQueue();
            g.queues.push_back(queue);
            Trace(queue, "Enqueue",
                MakeCallback(+[](Counters* c, Ptr<const WifiMpdu>) { c->enqueued++; }).Bind(c));
            Trace(queue, "Expired",
                MakeCallback(+[](Counters* c, Ptr<const WifiMpdu>) { c->queueExpired++; }).Bind(c));
        }
        Ptr<WifiPhy> wphy = g.wifi->GetPhy();
        Trace(wphy, "PhyTxDrop",
            MakeCallback(+[](Counters* c, Ptr<const Packet>) { c->phyTxDrops++; }).Bind(c));
        Trace(wphy, "PhyRxDrop",
            MakeCallback(+[](Counters* c, Ptr<const Packet>, WifiPhyRxfailureReason why) {
                c->phyRxDrops++;
                std::ostringstream s;
                s << why;
                c->phyRxDropReasons[s.str()]++;
            }).Bind(c));
        Trace(wphy->GetState(), "State",
            MakeCallback(+[](Counters* c, Time, Time duration, WifiPhyState state) {
                if (state == WifiPhyState::TX)
                    c->airtimeNs += duration.GetNanoSeconds();
            }).Bind(c));
    }
}

// ---- control ---------------------------------------------------------------------------------

std::string
StatsJson()
{
    std::ostringstream s;
    s << "{\"now_s\": " << Simulator::Now().GetSeconds() << ", \"qos\": "
      << (g_ghosts[0].wifi->GetMac()->GetQosSupported() ? "true" : "false")
      << ", \"lateness\": " << g_late.Json("probes")
      << ", \"relay_lag\": " << g_relay.Json("frames")
      << ", \"lag_file\": " << g_lagLog.Json() << ", \"robots\": [";
    for (size_t k = 0; k < g_ghosts.size(); ++k)
    {
        const Counters& c = g_ghosts[k].c;
        // In 3.37 the queue scheduler refuses an MPDU when the queue is full without firing
        // a drop trace (nor counting it): what the MAC accepted and never queued is the count.
        uint64_t queueDrops = c.macTx > c.enqueued ? c.macTx - c.enqueued : 0;
        uint32_t queued = 0;
        for (const auto& q : g_ghosts[k].queues)
        {
            queueDrops += q->GetTotalDroppedPackets();
            queued += q->GetNPackets();
        }
        s << (k ? ", " : "") << "{\"from_linux\": " << c.fromLinux
          << ", \"to_linux\": " << c.toLinux << ", \"foreign\": " << c.foreign
          << ", \"mac_tx\": " << c.macTx << ", \"retries\": " << c.retries
          << ", \"retry_drops\": " << c.retryDrops << ", \"mac_tx_drops\": " << c.macTxDrops
          << ", \"queue_drops\": " << queueDrops << ", \"queued\": " << queued  << ", \"queue_expired\": " << c.queueExpired
          << ", \"phy_tx_drops\": " << c.phyTxDrops << ", \"phy_rx_drops\": " << c.phyRxDrops
          << ", \"airtime_s\": " << c.airtimeNs / 1e9 << ", \"phy_rx_drop_reasons\": {";
        bool first = true;
        for (const auto& [why, count] : c.phyRxDropReasons)
        {
            s << (first ? "" : ", ") << "\"" << why << "\": " << count;
            first = false;
        }
        s << "}}";
    }
    s << "]}";
    return s.str();
}

// Runs inside the simulator thread: the request's effect and its answer.
std::string
Execute(const std::string& line)
{
    std::istringstream in(line);
    std::string verb;
    in >> verb;
    if (verb == "ping")
        return "ok";
    if (verb == "stats")
    {
        g_lagLog.Flush();
        return StatsJson();
    }
    if (verb == "flush")
    {
        g_lagLog.Flush();
        return "ok";
    }
    if (verb == "links")
    {
        std::ostringstream s;
        s << "links";
        for (size_t i = 0; i < g_ghosts.size(); ++i)
        {
            Ptr<WifiPhy> phy = g_ghosts[i].wifi->GetPhy();
            for (size_t j = i + 1; j < g_ghosts.size(); ++j)
            {
                double dbm = g_loss->CalcRxPower(phy->GetTxPowerStart(),
                                                 g_ghosts[i].mobility,
                                                 g_ghosts[j].mobility);
                if (dbm >= phy->GetRxSensitivity())
                    s << " " << i + 1 << "-" << j + 1;
            }
        }
        return s.str();
    }
    if (verb == "pos")
    {
        std::vector<double> xy;
        std::string word;
        while (in >> word)
        {
            char* end = nullptr;
            double v = std::strtod(word.c_str(), &end);
            if (*end != '\0' || !std::isfinite(v))
                return "error bad number " + word;
            xy.push_back(v);
        }
        if (xy.size() != 2 * g_ghosts.size())
            return "error want " + std::to_string(2 * g_ghosts.size()) + " numbers";
        for (size_t k = 0; k < g_ghosts.size(); ++k)
            g_ghosts[k].mobility->SetPosition(Vector(xy[2 * k], xy[2 * k + 1], 0));
        return "ok";
    }
    return "error unknown request " + verb;
}

std::string
InSimulator(const std::string& line)
{
    std::promise<std::string> answer;
    auto future = answer.get_future();
    Simulator::ScheduleWithContext(Simulator::NO_CONTEXT,
                                   Seconds(0),
                                   [&answer, &line] { answer.set_value(Execute(line)); });
    return future.get();
}

void
Serve(int client)
{
    std::string buffer;
    char chunk[4096];
    while (true)
    {
        ssize_t n = read(client, chunk, sizeof(chunk));
        if (n <= 0)
            break;
        buffer.append(chunk, static_cast<size_t>(n));
        size_t eol;
        while ((eol = buffer.find('\n')) != std::string::npos)
        {
            std::string reply = InSimulator(buffer.substr(0, eol)) + "\n";
            buffer.erase(0, eol + 1);
            if (write(client, reply.data(), reply.size()) != static_cast<ssize_t>(reply.size()))
                break;
        }
    }
    close(client);
}

int
Listen(const std::string& path)
{
    int fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    if (path.size() >= sizeof(addr.sun_path))
        Fail("socket path too long: " + path);
    std::strncpy(addr.sun_path, path.c_str(), sizeof(addr.sun_path) - 1);
    unlink(path.c_str());
    if (bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) < 0 || listen(fd, 8) < 0)
        Fail("control socket " + path + ": " + std::strerror(errno));
    return fd;
}

} // namespace

int
main(int argc, char** argv)
{
    Options o = ParseArgs(argc, argv);
    // The channel is part of the emulated world's clock: like the world's step loop it asks
    // for real-time priority for the simulator's thread (SCHED_RESET_ON_FORK: ns-3's reader
    // threads, started later, get normal scheduling), and falls back to nice -10 where that
    // is refused.
    if (o.rtPriority > 0)
    {
        sched_param param{};
        param.sched_priority = o.rtPriority;
        if (sched_setscheduler(0, SCHED_RR | SCHED_RESET_ON_FORK, &param) != 0 &&
            setpriority(PRIO_PROCESS, 0, -10) != 0)
            std::fprintf(stderr, "tb-ns3-wifi: no real-time priority nor nice -10\n");
    }
    GlobalValue::Bind("SimulatorImplementationType", StringValue("ns3::RealtimeSimulatorImpl"));
    GlobalValue::Bind("ChecksumEnabled", BooleanValue(false));
    auto impl = DynamicCast<RealtimeSimulatorImpl>(Simulator::GetImplementation());
    PeekPointer(impl)->*Get(SyncMember()) = Create<ScaledSynchronizer>(o.timeScale);

    g_timeScale = o.timeScale;
    if (!o.lagFile.empty())
        g_lagLog.Open(o.lagFile, o.lagCapBytes);
    Build(o);
    Simulator::Schedule(kProbeEvery, &LatenessProbe);

    int listener = Listen(o.socketPath);
    std::thread([listener] {
        while (true)
        {
            int client = accept4(listener, nullptr, nullptr, SOCK_CLOEXEC);
            if (client >= 0)
                std::thread(Serve, client).detach();
        }
    }).detach();

    std::printf("ready\n");
    std::fflush(stdout);
    Simulator::Stop(Days(3650)); // runs until SIGTERM
    Simulator::Run();
    return 0;
}
