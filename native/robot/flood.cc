#include "flood.h"

#include <arpa/inet.h>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <iterator>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include "json.h"

namespace tb {

namespace {
using gen::WINDOW;
}

DuplicateCache::Verdict DuplicateCache::check(int origin, uint32_t seq) {
    auto hi = high_.find(origin);
    uint32_t high = hi == high_.end() ? 0 : hi->second;
    int64_t d = seq_diff(seq, high);
    if (d > SEQ_WINDOW || d < -SEQ_WINDOW) return FORGED;
    auto& rec = recent_[origin];
    if (d <= -WINDOW || rec.count(seq)) return DUPLICATE;
    rec.insert(seq);
    if (d > 0) {
        high_[origin] = seq;
        if (static_cast<int64_t>(rec.size()) > 2 * WINDOW)
            for (auto it = rec.begin(); it != rec.end();)
                it = seq_diff(*it, seq) > -WINDOW ? std::next(it) : rec.erase(it);
    }
    return NEW;
}

int flood_seq_selftest(const std::string& in) {
    DuplicateCache cache;
    static const char* const names[] = {"new", "duplicate", "forged"};
    const char* p = in.c_str();
    long long origin = 0, seq = 0;
    int used = 0;
    while (sscanf(p, "%lld %lld%n", &origin, &seq, &used) == 2) {
        if (origin < 0 || origin > 65535 || seq < 0 || seq > 0xFFFFFFFFLL) {
            fprintf(stderr, "node: --decode floodseq: origin 0..65535, seq 0..2^32-1\n");
            return 2;
        }
        printf("%s\n", names[cache.check(static_cast<int>(origin), static_cast<uint32_t>(seq))]);
        p += used;
    }
    return 0;
}

Flooder::Flooder(int me, int port, std::string iface, const std::string& mode, double hold_s)
    : stats(), me_(me), port_(port), iface_(std::move(iface)), blind_(mode == "blind"),
      hold_(hold_s) {}

bool Flooder::open(std::string& err) {
    fd_.reset(socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0));
    const int fd = fd_.get();
    int one = 1, buf = gen::FLOOD_SOCKET_BUFFER;
    if (fd < 0 || setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one) ||
        setsockopt(fd, SOL_SOCKET, SO_BROADCAST, &one, sizeof one) ||
        setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &buf, sizeof buf) ||
        setsockopt(fd, SOL_SOCKET, SO_SNDBUF, &buf, sizeof buf) ||
        (!iface_.empty() &&
         setsockopt(fd, SOL_SOCKET, SO_BINDTODEVICE, iface_.c_str(), iface_.size()))) {
        err = std::string("flood socket: ") + strerror(errno);
        return false;
    }
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(static_cast<uint16_t>(port_));
    a.sin_addr.s_addr = htonl(INADDR_ANY);
    if (bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
        err = std::string("flood socket bind: ") + strerror(errno);
        return false;
    }
    return true;
}

std::vector<uint16_t> Flooder::neighbours(double now) {
    std::vector<uint16_t> out;
    for (const auto& kv : heard_)
        if (now - kv.second <= hold_) out.push_back(static_cast<uint16_t>(kv.first));
    return out;
}

void Flooder::note(const std::string& key) {
    std::lock_guard<std::mutex> g(counts_lock_);
    counts_.add(key);
}

double Flooder::count(const std::string& key) {
    std::lock_guard<std::mutex> g(counts_lock_);
    return counts_.get(key);
}

std::string Flooder::counts_json() {
    std::lock_guard<std::mutex> g(counts_lock_);
    return counts_.json_int();
}

bool Flooder::send(const std::string& data) {
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(static_cast<uint16_t>(port_));
    a.sin_addr.s_addr = htonl(INADDR_BROADCAST);
    if (sendto(fd_.get(), data.data(), data.size(), 0, reinterpret_cast<sockaddr*>(&a),
               sizeof a) < 0) {
        note("send_failed");
        return false;
    }
    return true;
}

uint32_t Flooder::originate(uint8_t kind, uint32_t step, const std::string& payload) {
    ++seq_;
    FloodHeader h;
    {
        std::lock_guard<std::mutex> g(cache_lock_);
        cache_.seen(me_, seq_);
        h.neighbours = neighbours(monotonic_s());
    }
    h.kind = kind;
    h.ttl = ttl_;
    h.origin = static_cast<uint16_t>(me_);
    h.seq = seq_;
    h.step = step;
    h.sender = static_cast<uint16_t>(me_);
    std::string data = pack_flood(h, payload);
    double t0 = monotonic_s();
    bool ok = send(data);
    if (kind == KIND_MAP) stats.note_publish(data.size(), ok, monotonic_s() - t0);
    return seq_;
}

bool Flooder::must_relay(int sender, int origin, const std::vector<uint16_t>& covered,
                         double now) {
    if (blind_) return true;
    for (uint16_t k : neighbours(now)) {
        if (k == sender || k == origin) continue;
        bool skip = false;
        for (uint16_t c : covered) skip = skip || c == k;
        if (!skip) return true;
    }
    return false;
}

std::vector<std::string> Flooder::receive_raw() {
    std::vector<std::string> out;
    std::vector<uint8_t>& buf = recv_buf_;
    double now = monotonic_s();
    while (true) {
        ssize_t got = recv(fd_.get(), buf.data(), buf.size(), 0);
        if (got < 0) return out;  // EAGAIN: drained
        const size_t n = static_cast<size_t>(got);
        FloodHeader h;
        std::string err;
        if (!unpack_flood(buf.data(), n, h, err)) {
            note("malformed");
            continue;
        }
        bool relay;
        std::vector<uint16_t> nb;
        {
            std::lock_guard<std::mutex> g(cache_lock_);
            if (h.sender != me_) heard_[h.sender] = now;
            auto verdict = h.origin == me_ ? DuplicateCache::DUPLICATE
                                           : cache_.check(h.origin, h.seq);
            if (verdict == DuplicateCache::FORGED) {
                note("forged");
                note("malformed");
                continue;
            }
            if (verdict == DuplicateCache::DUPLICATE) {
                note("duplicate");
                continue;
            }
            relay = h.ttl > 1 && must_relay(h.sender, h.origin, h.neighbours, now);
            if (relay) nb = neighbours(now);
        }
        if (relay) {
            const uint8_t ttl = static_cast<uint8_t>(h.ttl - 1);
            send(relayed(buf.data(), n, h, ttl, static_cast<uint16_t>(me_), nb));
            note("relayed");
        } else if (h.ttl > 1) {
            note("pruned");
        }
        if (h.kind == KIND_MAP) stats.note_receive(h.origin, n);
        out.emplace_back(reinterpret_cast<const char*>(buf.data()), n);
    }
}

}  // namespace tb
