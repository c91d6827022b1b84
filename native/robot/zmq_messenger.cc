// ZeroMQ (node/messaging/zeromq.py, zmqsockets.py) with libzmq's C API: a PULL socket bound to
// the robot's address to hear, one PUSH per teammate, each set up as the Python robot's:
// ZMQ_IMMEDIATE 1 (queue only to a completed connection), ZMQ_SNDTIMEO the send timeout,
// ZMQ_SNDHWM 8, ZMQ_LINGER 0, ZMQ_RECONNECT_IVL / _MAX the reconnect back-off; heartbeats off.
//
// A ZeroMQ socket is not thread-safe and a robot sends from two threads, receives from a third
// and closes from a fourth: each socket has its own lock, held for the whole of a send. close()
// terminates the context in a thread of its own (every call blocked inside ZeroMQ returns
// ETERM, so each lock comes free) while it closes the sockets under their locks.
//
// fileno() is the listening socket's ZMQ_FD: readable when its state may have changed, after
// which receive() reads to EAGAIN (as ZeroMQ's documentation asks) and reads ZMQ_EVENTS, so
// that the next message makes it readable again.
//
// Built only where make setup found libzmq3-dev (TB_WITH_ZMQ); elsewhere the C++ robot carries
// nanomsg alone and `--robot auto` runs the Python robot for --middleware zeromq.
#include "messenger.h"
#include "robot_consts.h"

#ifdef TB_WITH_ZMQ

#include <algorithm>
#include <cerrno>
#include <map>
#include <mutex>
#include <thread>

#include <zmq.h>

#include "log.h"

namespace tb {

namespace {

constexpr int SEND_HWM = gen::SEND_QUEUE;  // messages queued per teammate (pyzmq's)

struct Sock {
    void* sock = nullptr;
    std::mutex lock;  // held for the whole of a call on `sock`
};

bool set_int(void* s, int option, int value) {
    return zmq_setsockopt(s, option, &value, sizeof value) == 0;
}

class ZmqMessenger : public Messenger {
public:
    ZmqMessenger(int me, const MessengerTimings& t)
        : me_(me), port_(t.port), send_timeout_ms_(std::max(1, t.send_timeout_ms)),
          reconnect_min_(std::max(1, t.reconnect_min_ms)),
          reconnect_max_(std::max(reconnect_min_, t.reconnect_max_ms)) {
        ctx_ = zmq_ctx_new();
        if (ctx_) zmq_ctx_set(ctx_, ZMQ_IO_THREADS, 1);
    }
    ~ZmqMessenger() override { close(); }
    ZmqMessenger(const ZmqMessenger&) = delete;
    ZmqMessenger& operator=(const ZmqMessenger&) = delete;

    const char* name() const override { return "zeromq"; }
    int fileno() const override { return fd_; }

    bool open(const std::string& bind_addr, std::string& err) override {
        std::string where = bind_addr + ":" + std::to_string(port_);
        if (!ctx_) {
            err = std::string("zeromq: no context: ") + zmq_strerror(errno);
            return false;
        }
        std::lock_guard<std::mutex> g(rx_.lock);
        rx_.sock = zmq_socket(ctx_, ZMQ_PULL);
        if (!rx_.sock) {
            err = std::string("zeromq: ") + zmq_strerror(errno);
            return false;
        }
        std::string url = "tcp://" + where;
        size_t len = sizeof fd_;
        if (!set_int(rx_.sock, ZMQ_LINGER, 0) || zmq_bind(rx_.sock, url.c_str()) != 0 ||
            zmq_getsockopt(rx_.sock, ZMQ_FD, &fd_, &len) != 0) {
            err = "zeromq: cannot listen on " + where + ": " + zmq_strerror(errno);
            return false;
        }
        return true;
    }

    void connect(int j) override { peer(j); }

    bool send(int j, const std::string& data) override {
        int64_t token = stats.send_started();
        bool ok = false;
        if (Sock* p = peer(j)) {
            std::lock_guard<std::mutex> g(p->lock);
            // EAGAIN: no connected teammate, or its queue full, for the send timeout;
            // ETERM: closed meanwhile.
            if (p->sock) ok = zmq_send(p->sock, data.data(), data.size(), 0) >= 0;
        }
        stats.send_ended(token, ok);
        return ok;
    }

    std::vector<std::string> receive() override {
        std::vector<std::string> out;
        {
            std::lock_guard<std::mutex> g(rx_.lock);
            if (!rx_.sock) return out;
            while (true) {
                zmq_msg_t m;
                zmq_msg_init(&m);
                if (zmq_msg_recv(&m, rx_.sock, ZMQ_DONTWAIT) < 0) {
                    zmq_msg_close(&m);
                    break;  // EAGAIN: read to the end; ETERM: closed meanwhile
                }
                out.emplace_back(static_cast<const char*>(zmq_msg_data(&m)), zmq_msg_size(&m));
                zmq_msg_close(&m);
            }
            int events = 0;
            size_t len = sizeof events;
            zmq_getsockopt(rx_.sock, ZMQ_EVENTS, &events, &len);  // re-arms ZMQ_FD
        }
        std::lock_guard<std::mutex> g(stats.lock);
        stats.received += static_cast<int64_t>(out.size());
        return out;
    }

    void close() override {
        {
            std::lock_guard<std::mutex> g(lock_);
            if (closed_) return;
            closed_ = true;
        }
        void* ctx = ctx_;
        std::thread term;
        if (ctx) term = std::thread([ctx] { while (zmq_ctx_term(ctx) != 0 && errno == EINTR) {} });
        auto shut = [](Sock& s) {
            std::lock_guard<std::mutex> g(s.lock);
            if (s.sock) zmq_close(s.sock);
            s.sock = nullptr;
        };
        shut(rx_);
        for (auto& kv : peers_) shut(*kv.second);  // closed_: no peer is added any more
        if (term.joinable()) term.join();
        ctx_ = nullptr;
    }

private:
    // Teammate j's socket, made and connected on first use; nullptr once closed.
    Sock* peer(int j) {
        std::lock_guard<std::mutex> g(lock_);
        if (closed_) return nullptr;
        auto it = peers_.find(j);
        if (it != peers_.end()) return it->second.get();
        void* s = zmq_socket(ctx_, ZMQ_PUSH);
        std::string url = "tcp://" + robot_addr(j) + ":" + std::to_string(port_);
        // A socket without its send timeout would block a send for good: none rather than
        // that (the send fails, counted, and the next one tries again).
        bool ok = s && set_int(s, ZMQ_LINGER, 0) &&
                  set_int(s, ZMQ_RECONNECT_IVL, reconnect_min_) &&
                  set_int(s, ZMQ_RECONNECT_IVL_MAX, reconnect_max_) &&
                  set_int(s, ZMQ_IMMEDIATE, 1) && set_int(s, ZMQ_SNDTIMEO, send_timeout_ms_) &&
                  set_int(s, ZMQ_SNDHWM, SEND_HWM) &&
                  zmq_connect(s, url.c_str()) == 0;  // connects and reconnects in the background
        if (!ok) {
            LOG_WARN("node.messaging", "socket to r%d: %s", j, zmq_strerror(zmq_errno()));
            if (s) zmq_close(s);
            return nullptr;
        }
        auto made = std::make_unique<Sock>();
        made->sock = s;
        return (peers_[j] = std::move(made)).get();
    }

    int me_, port_, send_timeout_ms_, reconnect_min_, reconnect_max_;
    void* ctx_ = nullptr;
    int fd_ = -1;
    Sock rx_;
    std::mutex lock_;  // guards peers_ and closed_
    bool closed_ = false;
    std::map<int, std::unique_ptr<Sock>> peers_;
};

}  // namespace

std::unique_ptr<Messenger> make_zmq_messenger(int me, const MessengerTimings& t) {
    return std::make_unique<ZmqMessenger>(me, t);
}

std::string carried_middlewares() { return "nanomsg zeromq"; }

}  // namespace tb

#else  // built without libzmq3-dev

namespace tb {

std::unique_ptr<Messenger> make_zmq_messenger(int, const MessengerTimings&) { return nullptr; }

std::string carried_middlewares() { return "nanomsg"; }

}  // namespace tb

#endif
