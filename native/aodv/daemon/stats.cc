// See stats.h.
#include "stats.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <fcntl.h>
#include <cstring>
#include <ctime>
#include <fstream>
#include <sstream>
#include <sys/stat.h>
#include <unistd.h>

#include "../core.h"
#include "aodv_consts.h"
#include "log.h"

namespace aodv {

double wall_now() {
    timespec ts{};
    clock_gettime(CLOCK_REALTIME, &ts);
    return double(ts.tv_sec) + double(ts.tv_nsec) * 1e-9;
}

double mono_now() {
    timespec ts{};
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return double(ts.tv_sec) + double(ts.tv_nsec) * 1e-9;
}

namespace {
constexpr size_t N_BOUNDS = sizeof gen::TIMER_BOUNDS_MS / sizeof gen::TIMER_BOUNDS_MS[0];
static_assert(N_BOUNDS == 5, "TimerLateness keeps N_BOUNDS + 1 counts");

json::Value counts(const Counts& c) {
    json::Value v = json::Value::object();
    for (const auto& [k, n] : c) v[k] = json::Value::integer(n);
    return v;
}
}  // namespace

void TimerLateness::add(double late_ms, double due, double fired) {
    ++n_;
    late_ += late_ms > 0;
    max_ = std::max(max_, late_ms);
    size_t i = N_BOUNDS;
    for (size_t b = 0; b < N_BOUNDS; ++b)
        if (late_ms <= gen::TIMER_BOUNDS_MS[b]) {
            i = b;
            break;
        }
    ++counts_[i];
    auto cmp = std::greater<>();  // a min-heap on (ms late, due, fired)
    if (worst_.size() < size_t(gen::WORST_KEPT)) {
        worst_.emplace_back(late_ms, due, fired);
        std::push_heap(worst_.begin(), worst_.end(), cmp);
    } else if (late_ms > std::get<0>(worst_.front())) {
        std::pop_heap(worst_.begin(), worst_.end(), cmp);
        worst_.back() = {late_ms, due, fired};
        std::push_heap(worst_.begin(), worst_.end(), cmp);
    }
}

json::Value TimerLateness::as_json() const {
    json::Value v = json::Value::object();
    v["n"] = json::Value::integer(n_);
    v["late"] = json::Value::integer(late_);
    v["max"] = json::Value::real(json::py_round(max_, 3));
    json::Value hist = json::Value::object();
    for (size_t b = 0; b < N_BOUNDS; ++b)
        hist["<=" + std::to_string(gen::TIMER_BOUNDS_MS[b])] = json::Value::integer(counts_[b]);
    hist[">" + std::to_string(gen::TIMER_BOUNDS_MS[N_BOUNDS - 1])] =
        json::Value::integer(counts_[N_BOUNDS]);
    v["hist"] = std::move(hist);
    // [due, fired, ms late], in the order they were due (Python's sort is stable: ties keep
    // the heap's order, which only equal due times could tell apart).
    auto w = worst_;
    std::stable_sort(w.begin(), w.end(),
                     [](const auto& a, const auto& b) { return std::get<1>(a) < std::get<1>(b); });
    json::Value list = json::Value::array();
    for (const auto& [ms, d, f] : w) {
        json::Value row = json::Value::array();
        row.arr.push_back(json::Value::real(json::py_round(d, 4)));
        row.arr.push_back(json::Value::real(json::py_round(f, 4)));
        row.arr.push_back(json::Value::real(json::py_round(ms, 3)));
        list.arr.push_back(std::move(row));
    }
    v["worst"] = std::move(list);
    return v;
}

Stats::Stats(std::string r, std::string a) : robot(std::move(r)), addr(std::move(a)) {
    started = wall_now();
}

std::string Stats::text(bool compact) {
    using json::Value;
    Value v = Value::object();
    v["robot"] = Value::str(robot);
    v["addr"] = Value::str(addr);
    v["pid"] = Value::integer(getpid());
    v["uptime_s"] = Value::real(json::py_round(wall_now() - started, 3));
    v["messages_sent"] = counts(sent);
    v["messages_not_transmitted"] = counts(not_transmitted);
    v["bytes_not_transmitted"] = Value::integer(bytes_not_transmitted);
    v["messages_received"] = counts(received);
    v["bytes_sent"] = Value::integer(bytes_sent);
    v["bytes_received"] = Value::integer(bytes_received);
    v["protocol_dropped"] = counts(protocol_dropped);
    Value rs = Value::object();
    for (const auto& [dest, nh] : routes) {
        Value r = Value::object();
        r["next_hop"] = Value::str(nh.first);
        r["hops"] = Value::integer(nh.second);
        rs[dest] = std::move(r);
    }
    v["routes"] = std::move(rs);
    v["packets_buffered"] = Value::integer(packets_buffered);
    v["route_use_refreshes"] = Value::integer(route_uses);
    {
        std::lock_guard<std::mutex> lock(kmu);
        Counts drops = dropped;
        for (const auto& [reason, n] : k.dropped) drops[reason] += n;
        v["dropped"] = counts(drops);
        v["local_repairs"] = counts(k.local_repairs);
        v["route_installs"] = Value::integer(k.route_installs);
        v["route_deletes"] = Value::integer(k.route_deletes);
        v["packets_released"] = Value::integer(k.packets_released);
        v["icmp_unreachable_sent"] = Value::integer(k.icmp_unreachable);
        v["discoveries_ok"] = Value::integer(k.discoveries_ok);
        v["discoveries_failed"] = Value::integer(k.discoveries_failed);
        Value ds = Value::array();
        for (const auto& d : k.discoveries) {
            Value x = Value::object();
            x["dest"] = Value::str(d.dest);
            x["ok"] = Value::boolean(d.ok);
            x["latency_s"] = Value::real(d.latency_s);
            x["round_latency_s"] = Value::real(d.round_latency_s);
            x["t"] = Value::real(d.t);
            ds.arr.push_back(std::move(x));
        }
        v["discoveries"] = std::move(ds);
    }
    Value tl = Value::object();
    tl["hello"] = hello.as_json();
    tl["expiry"] = expiry.as_json();
    v["timer_lateness_ms"] = std::move(tl);
    timespec cpu{};
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &cpu);
    v["cpu_s"] = Value::real(json::py_round(double(cpu.tv_sec) + double(cpu.tv_nsec) * 1e-9, 3));
    return json::dump(v, compact ? -1 : 1) + "\n";
}

// -- StatsWriter ---------------------------------------------------------------------------------
StatsWriter::StatsWriter(std::string path) : path_(std::move(path)) {
    thread_ = std::thread([this] { run(); });
}

StatsWriter::~StatsWriter() { close(); }

void StatsWriter::submit(std::string text) {
    {
        std::lock_guard<std::mutex> lock(mu_);
        pending_ = std::move(text);
    }
    cv_.notify_one();
}

void StatsWriter::close() {
    if (!thread_.joinable()) return;
    {
        std::lock_guard<std::mutex> lock(mu_);
        closing_ = true;
    }
    cv_.notify_one();
    thread_.join();
}

void StatsWriter::run() {
    for (;;) {
        std::optional<std::string> text;
        bool closing;
        {
            std::unique_lock<std::mutex> lock(mu_);
            cv_.wait(lock, [this] { return pending_.has_value() || closing_; });
            text.swap(pending_);
            closing = closing_;
        }
        if (text) {
            std::string err;
            if (!json::write_atomic(path_, *text, &err) && ++failures_ % 100 == 1)
                AODV_LOG(WARNING, "aodv.statswriter",
                         "statistics file %s not written (%lld times): %s", path_.c_str(),
                         failures_, err.c_str());
        }
        if (closing) return;
    }
}

// -- CounterStore ----------------------------------------------------------------------------
bool CounterStore::load(uint32_t& seq, uint32_t& rreq_id) {
    int fd = open(path_.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
    if (fd < 0 && errno == ENOENT) return false;
    std::string text;
    bool readable = false;
    if (fd >= 0) {
        struct stat st {};
        // A regular file of sane size (common.boundedfile refuses FIFOs and huge files).
        if (fstat(fd, &st) == 0 && S_ISREG(st.st_mode) && st.st_size < (1 << 20)) {
            char buf[4096];
            ssize_t n;
            readable = true;
            while ((n = read(fd, buf, sizeof buf)) > 0) text.append(buf, size_t(n));
            if (n < 0) readable = false;
        }
        close(fd);
    }
    json::Value v;
    auto number = [](const json::Value* x, uint32_t& out) {
        if (x == nullptr) return false;
        // int(x) & MASK: whole numbers, floats (truncated), booleans.
        if (x->t == json::Value::Int) out = uint32_t(uint64_t(x->i));
        else if (x->t == json::Value::Bool) out = x->b;
        else if (x->t == json::Value::Real && std::isfinite(x->d) && std::fabs(x->d) < 9e18)
            out = uint32_t(uint64_t((long long)x->d));
        else return false;
        return true;
    };
    if (readable && json::parse(text, v) && number(v.get("seq"), seq) &&
        number(v.get("rreq_id"), rreq_id)) {
        marked_ = true;
        seq_mark_ = seq;
        id_mark_ = rreq_id;
        return true;
    }
    AODV_LOG(WARNING, "aodv.persist", "counter file %s unreadable: numbers start again from 0",
             path_.c_str());
    seq = rreq_id = 0;
    return true;
}

void CounterStore::cover(uint32_t seq, uint32_t rreq_id) {
    if (marked_ && seqnum::newer(seq_mark_, seq) && seqnum::newer(id_mark_, rreq_id)) return;
    seq_mark_ = seq + uint32_t(gen::COUNTER_BLOCK);
    id_mark_ = rreq_id + uint32_t(gen::COUNTER_BLOCK);
    marked_ = true;
    std::string text = "{\n \"seq\": " + std::to_string(seq_mark_) + ",\n \"rreq_id\": " +
                       std::to_string(id_mark_) + "\n}\n";
    std::string err;
    if (!json::write_atomic(path_, text, &err))
        AODV_LOG(ERROR, "aodv.persist", "counter file %s not written: %s", path_.c_str(),
                 err.c_str());
}

}  // namespace aodv
