// nanomsg, the default middleware (node/messaging/nanomsg.py), with nng's C API: a PULL
// socket listening on the robot's address to hear, one PUSH per teammate dialled in the
// background. A send waits at most the send timeout for a connected peer, then gives up;
// redials back off from reconnect min to max. The same options as the Python robot's.
#pragma once

#include <map>
#include <mutex>
#include <string>
#include <vector>

#include <nng/nng.h>
#include <nng/protocol/pipeline0/pull.h>
#include <nng/protocol/pipeline0/push.h>

#include "stats.h"

namespace tb {

class Messenger {
public:
    Messenger(int me, int port, int send_timeout_ms, int reconnect_min_ms, int reconnect_max_ms);
    ~Messenger();
    Messenger(const Messenger&) = delete;
    Messenger& operator=(const Messenger&) = delete;
    bool open(const std::string& bind_addr, std::string& err);
    int fileno() const { return recv_fd_; }
    void connect(int j);
    bool send(int j, const std::string& data);
    std::vector<std::string> receive();
    void close();
    MessengerStats stats;

private:
    nng_socket* push_socket(int j);  // lock held

    int me_, port_, send_timeout_ms_, reconnect_min_, reconnect_max_;
    nng_socket pull_ = NNG_SOCKET_INITIALIZER;
    bool pull_open_ = false;
    int recv_fd_ = -1;
    std::mutex lock_;  // guards push_ (the planner and message processing both send)
    std::map<int, nng_socket> push_;
};

// Robot k's address (topology.names.robot_addr): 10.0.hi.lo+1.
std::string robot_addr(int k);

}  // namespace tb
