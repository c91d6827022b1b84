#include "messenger.h"

#include <algorithm>

#include "log.h"

namespace tb {

std::string robot_addr(int k) {
    int hi = (k - 1) / 254, lo = (k - 1) % 254;
    return "10.0." + std::to_string(hi) + "." + std::to_string(lo + 1);
}

Messenger::Messenger(int me, int port, int send_timeout_ms, int reconnect_min_ms,
                     int reconnect_max_ms)
    : me_(me), port_(port), send_timeout_ms_(std::max(1, send_timeout_ms)),
      reconnect_min_(std::max(1, reconnect_min_ms)),
      reconnect_max_(std::max(std::max(1, reconnect_min_ms), reconnect_max_ms)) {}

Messenger::~Messenger() { close(); }

bool Messenger::open(const std::string& bind_addr, std::string& err) {
    int rv = nng_pull0_open(&pull_);
    if (rv == 0) {
        pull_open_ = true;
        std::string url = "tcp://" + bind_addr + ":" + std::to_string(port_);
        rv = nng_listen(pull_, url.c_str(), nullptr, 0);
    }
    if (rv == 0) rv = nng_socket_get_int(pull_, NNG_OPT_RECVFD, &recv_fd_);
    if (rv != 0) {
        err = std::string("nanomsg: ") + nng_strerror(rv);
        return false;
    }
    return true;
}

nng_socket* Messenger::push_socket(int j) {
    auto it = push_.find(j);
    if (it != push_.end()) return &it->second;
    nng_socket s;
    if (nng_push0_open(&s) != 0) return nullptr;
    nng_socket_set_ms(s, NNG_OPT_SENDTIMEO, send_timeout_ms_);
    nng_socket_set_ms(s, NNG_OPT_RECONNMINT, reconnect_min_);
    nng_socket_set_ms(s, NNG_OPT_RECONNMAXT, reconnect_max_);
    nng_socket_set_int(s, NNG_OPT_SENDBUF, 8);
    std::string url = "tcp://" + robot_addr(j) + ":" + std::to_string(port_);
    int rv = nng_dial(s, url.c_str(), nullptr, NNG_FLAG_NONBLOCK);
    if (rv != 0) LOG_WARN("node.messaging", "dial r%d: %s", j, nng_strerror(rv));
    return &(push_[j] = s);
}

void Messenger::connect(int j) {
    std::lock_guard<std::mutex> g(lock_);
    push_socket(j);
}

bool Messenger::send(int j, const std::string& data) {
    int64_t token = stats.send_started();
    nng_socket s;
    bool have;
    {
        std::lock_guard<std::mutex> g(lock_);
        nng_socket* p = push_socket(j);
        have = p != nullptr;
        if (have) s = *p;
    }
    // nng sockets are thread-safe: the send itself runs outside the lock.
    bool ok = have && nng_send(s, (void*)data.data(), data.size(), 0) == 0;
    stats.send_ended(token, ok);
    return ok;
}

std::vector<std::string> Messenger::receive() {
    std::vector<std::string> out;
    while (pull_open_) {
        char* buf = nullptr;
        size_t n = 0;
        if (nng_recv(pull_, &buf, &n, NNG_FLAG_ALLOC | NNG_FLAG_NONBLOCK) != 0) break;
        out.emplace_back(buf, n);
        nng_free(buf, n);
    }
    std::lock_guard<std::mutex> g(stats.lock);
    stats.received += (int64_t)out.size();
    return out;
}

void Messenger::close() {
    std::lock_guard<std::mutex> g(lock_);
    for (auto& kv : push_) nng_close(kv.second);
    push_.clear();
    if (pull_open_) nng_close(pull_);
    pull_open_ = false;
}

}  // namespace tb
