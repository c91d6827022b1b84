// The compiled daemon's hands (aodv/actuator.py): the core's actions carried out in the
// core's order. Control messages leave from the loop; route changes and what must follow a
// route (releases, drops, the discovery's record) go, one batch per event, in order, to one
// kernel thread, so an rtnetlink request held up on the kernel's rtnl lock never holds the
// HELLO and expiry timers back. Before a batch leaves, the counters it may carry are on disk
// (RFC 6.13, CounterStore).
#pragma once

#include <condition_variable>
#include <deque>
#include <mutex>
#include <thread>
#include <vector>

#include "../core.h"
#include "control.h"
#include "kernel.h"
#include "stats.h"

namespace aodv {

class Actuator {
  public:
    Actuator(AodvCore& core, ControlChannel& control, KernelRoutes& routes, int raw, Tun& tun,
             Stats& stats, CounterStore* store);
    ~Actuator();
    void execute(std::vector<Action>&& actions, double now);
    // Carry out what was handed to the kernel thread, then stop it (idempotent).
    void close();
    // The kernel's answers to our route changes: a refusal is counted and logged.
    void read_route_acks();

  private:
    struct Batch {
        std::vector<Action> actions;
        double now;
    };
    void run();
    void kernel_batch(Batch& b);
    bool route_change(bool install, const Action& a);
    void discovery_done(const Action& a, double now, double routed);

    AodvCore& core_;
    ControlChannel& control_;
    KernelRoutes& routes_;
    int raw_;
    Tun& tun_;
    Stats& stats_;
    CounterStore* store_;
    std::mutex mu_;
    std::condition_variable cv_;
    std::deque<Batch> jobs_;
    bool closing_ = false;
    std::thread thread_;
};

// Real-time priority for the calling thread (common/sched.py's raise_priority): SCHED_RR with
// SCHED_RESET_ON_FORK, else a nice value, else nothing; what it got.
std::string raise_priority(int rt_priority, int nice);

}  // namespace aodv
