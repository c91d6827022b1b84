// nanomsg, the default middleware (node/messaging/nanomsg.py), with nng's C API: a PULL
// socket listening on the robot's address to hear, one PUSH per teammate dialled in the
// background. nng's sockets are thread-safe, so a send runs outside the messenger's lock.
// The same options as the Python robot's.
#include <algorithm>
#include <map>
#include <mutex>

#include <nng/nng.h>
#include <nng/protocol/pipeline0/pull.h>
#include <nng/protocol/pipeline0/push.h>

#include "log.h"
#include "messenger.h"
#include "robot_consts.h"

namespace tb {

std::unique_ptr<Messenger> make_zmq_messenger(int me, const MessengerTimings& t);

namespace {

constexpr int SEND_BUFFER = gen::SEND_QUEUE;  // messages queued per teammate (pynng's)

class NngMessenger : public Messenger {
public:
    NngMessenger(int me, const MessengerTimings& t)
        : me_(me), port_(t.port), send_timeout_ms_(std::max(1, t.send_timeout_ms)),
          reconnect_min_(std::max(1, t.reconnect_min_ms)),
          reconnect_max_(std::max(reconnect_min_, t.reconnect_max_ms)) {}
    ~NngMessenger() override { close(); }
    NngMessenger(const NngMessenger&) = delete;
    NngMessenger& operator=(const NngMessenger&) = delete;

    const char* name() const override { return "nanomsg"; }
    int fileno() const override { return recv_fd_; }

    bool open(const std::string& bind_addr, std::string& err) override {
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

    void connect(int j) override {
        std::lock_guard<std::mutex> g(lock_);
        push_socket(j);
    }

    bool send(int j, const std::string& data) override {
        int64_t token = stats.send_started();
        nng_socket s;
        bool have;
        {
            std::lock_guard<std::mutex> g(lock_);
            nng_socket* p = push_socket(j);
            have = p != nullptr;
            if (have) s = *p;
        }
        // nng_send's buffer is not const but, without NNG_FLAG_ALLOC, only read.
        void* bytes = const_cast<char*>(data.data());
        bool ok = have && nng_send(s, bytes, data.size(), 0) == 0;
        stats.send_ended(token, ok);
        return ok;
    }

    std::vector<std::string> receive() override {
        std::vector<std::string> out;
        while (pull_open_) {
            char* buf = nullptr;
            size_t n = 0;
            if (nng_recv(pull_, &buf, &n, NNG_FLAG_ALLOC | NNG_FLAG_NONBLOCK) != 0) break;
            out.emplace_back(buf, n);
            nng_free(buf, n);
        }
        std::lock_guard<std::mutex> g(stats.lock);
        stats.received += static_cast<int64_t>(out.size());
        return out;
    }

    void close() override {
        std::lock_guard<std::mutex> g(lock_);
        for (auto& kv : push_) nng_close(kv.second);
        push_.clear();
        if (pull_open_) nng_close(pull_);
        pull_open_ = false;
    }

private:
    nng_socket* push_socket(int j) {  // lock held
        auto it = push_.find(j);
        if (it != push_.end()) return &it->second;
        nng_socket s = NNG_SOCKET_INITIALIZER;
        int rv = nng_push0_open(&s);
        // A socket without its send timeout would block a send for good: none rather than
        // that (the send fails, counted, and the next one tries again).
        if (rv == 0) rv = nng_socket_set_ms(s, NNG_OPT_SENDTIMEO, send_timeout_ms_);
        if (rv == 0) rv = nng_socket_set_ms(s, NNG_OPT_RECONNMINT, reconnect_min_);
        if (rv == 0) rv = nng_socket_set_ms(s, NNG_OPT_RECONNMAXT, reconnect_max_);
        if (rv == 0) rv = nng_socket_set_int(s, NNG_OPT_SENDBUF, SEND_BUFFER);
        if (rv != 0) {
            if (nng_socket_id(s) > 0) nng_close(s);
            LOG_WARN("node.messaging", "socket to r%d: %s", j, nng_strerror(rv));
            return nullptr;
        }
        std::string url = "tcp://" + robot_addr(j) + ":" + std::to_string(port_);
        rv = nng_dial(s, url.c_str(), nullptr, NNG_FLAG_NONBLOCK);
        if (rv != 0) LOG_WARN("node.messaging", "dial r%d: %s", j, nng_strerror(rv));
        return &(push_[j] = s);
    }

    int me_, port_, send_timeout_ms_, reconnect_min_, reconnect_max_;
    nng_socket pull_ = NNG_SOCKET_INITIALIZER;
    bool pull_open_ = false;
    int recv_fd_ = -1;
    std::mutex lock_;  // guards push_ (the planner and message processing both send)
    std::map<int, nng_socket> push_;
};

}  // namespace

std::string robot_addr(int k) {
    int hi = (k - 1) / gen::ADDRS_PER_OCTET, lo = (k - 1) % gen::ADDRS_PER_OCTET;
    return std::to_string(gen::NET_OCTET_A) + "." + std::to_string(gen::NET_OCTET_B) + "." +
           std::to_string(hi) + "." + std::to_string(lo + 1);
}

std::unique_ptr<Messenger> make_messenger(const std::string& middleware, int me,
                                          const MessengerTimings& t) {
    if (middleware == "nanomsg") return std::make_unique<NngMessenger>(me, t);
    if (middleware == "zeromq") return make_zmq_messenger(me, t);
    return nullptr;
}

}  // namespace tb
