// Counters of one compiled AODV daemon and its statistics file, key for key the Python
// daemon's (aodv/stats.py, aodv/statsfile.py: DaemonStats reads either unchanged), and the
// writer thread that rewrites the file off the loop (aodv/statswriter.py).
//
// Threads: the loop owns `Stats` but for `KernelCounts`, which the kernel thread (the
// actuator's) adds to under `kmu`; the loop locks it only to take a snapshot.
#pragma once

#include <cstdint>
#include <condition_variable>
#include <deque>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "json.h"

namespace aodv {

using Counts = std::map<std::string, long long>;

// How late one kind of timer fired, in emulated ms (aodv.stats.TimerLateness).
class TimerLateness {
  public:
    void add(double late_ms, double due, double fired);
    json::Value as_json() const;

  private:
    long long n_ = 0, late_ = 0;
    double max_ = 0;
    std::vector<long long> counts_ = std::vector<long long>(6, 0);
    // A min-heap of (ms late, due, fired): the WORST_KEPT most late.
    std::vector<std::tuple<double, double, double>> worst_;
};

struct DiscoveryRecord {
    std::string dest;
    bool ok;
    double latency_s, round_latency_s, t;
};

// What the kernel thread counts (under Stats::kmu).
struct KernelCounts {
    long long route_installs = 0, route_deletes = 0, packets_released = 0, icmp_unreachable = 0;
    long long discoveries_ok = 0, discoveries_failed = 0;
    std::deque<DiscoveryRecord> discoveries;  // the newest 1000, as the file keeps them
    Counts local_repairs, dropped;
};

struct Stats {
    Stats(std::string robot, std::string addr);
    std::string robot, addr;
    double started;  // wall clock
    Counts sent, received, dropped, not_transmitted, protocol_dropped;
    long long bytes_sent = 0, bytes_received = 0, bytes_not_transmitted = 0;
    long long packets_buffered = 0, route_uses = 0;
    std::vector<std::pair<std::string, std::pair<std::string, int>>> routes;  // dest, (nh, hops)
    TimerLateness hello, expiry;
    std::mutex kmu;
    KernelCounts k;

    // The file's contents: compact (one line) or indented by one space (the last write).
    std::string text(bool compact);
};

// Writes the newest submitted text to `path` on a thread of its own.
class StatsWriter {
  public:
    explicit StatsWriter(std::string path);
    ~StatsWriter();
    void submit(std::string text);  // returns at once
    void close();                   // write what waits, stop the thread (idempotent)

  private:
    void run();
    std::string path_;
    std::mutex mu_;
    std::condition_variable cv_;
    std::optional<std::string> pending_;
    bool closing_ = false;
    long long failures_ = 0;
    std::thread thread_;
};

// RFC 6.13 counter file (aodv/persist.py): high-water marks of the sequence number and RREQ
// ID, COUNTER_BLOCK ahead, on disk before a message carrying a higher value leaves.
class CounterStore {
  public:
    explicit CounterStore(std::string path) : path_(std::move(path)) {}
    // (seq, rreq_id) to resume from; false on a first start (no file).
    bool load(uint32_t& seq, uint32_t& rreq_id);
    void cover(uint32_t seq, uint32_t rreq_id);

  private:
    std::string path_;
    bool marked_ = false;
    uint32_t seq_mark_ = 0, id_mark_ = 0;
};

double wall_now();
double mono_now();

}  // namespace aodv
