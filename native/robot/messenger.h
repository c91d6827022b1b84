// The goal messages' middleware (node/messaging/): one listening socket to hear, one socket per
// teammate to send on, the same contract as the Python robot's messengers (docs/
// robot-contract.md). A send waits at most the send timeout for a connected peer, then gives
// up; reconnects back off from reconnect min to max; the counters are MessengerStats.
// Two implementations: nanomsg's PUSH/PULL with nng (nng_messenger.cc, always) and ZeroMQ's
// PUSH/PULL with libzmq (zmq_messenger.cc, where make setup found libzmq3-dev).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "stats.h"

namespace tb {

class Messenger {
public:
    virtual ~Messenger() = default;
    // The run's --middleware value this messenger carries ("nanomsg", "zeromq").
    virtual const char* name() const = 0;
    virtual bool open(const std::string& bind_addr, std::string& err) = 0;
    // A descriptor that is readable when receive() may have something (poll it).
    virtual int fileno() const = 0;
    virtual void connect(int j) = 0;
    virtual bool send(int j, const std::string& data) = 0;
    virtual std::vector<std::string> receive() = 0;
    virtual void close() = 0;
    MessengerStats stats;
};

struct MessengerTimings {
    int port, send_timeout_ms, reconnect_min_ms, reconnect_max_ms;
};

// The messenger for --middleware `middleware`, or nullptr where this build does not carry it.
std::unique_ptr<Messenger> make_messenger(const std::string& middleware, int me,
                                          const MessengerTimings& t);

// The middlewares this build carries, space-separated ("nanomsg zeromq").
std::string carried_middlewares();

// Robot k's address (topology.names.robot_addr; its numbers from robot_consts.h).
std::string robot_addr(int k);

}  // namespace tb
