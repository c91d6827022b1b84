// Scheduling priority for the threads that keep deadlines (common/sched.py): SCHED_RR 1 for
// motion control, the planner and the timer, reset in children, else nice -5, else normal;
// TESTBED_REALTIME=0 turns real-time priority off.
#pragma once

#include <string>

#include "robot_consts.h"

namespace tb {

using gen::DEADLINE_NICE;
using gen::DEADLINE_RT;

// Raises the calling thread's priority; returns what it got ("SCHED_RR 1", "nice -5", "normal").
std::string raise_priority(int rt_priority, int nice);

}  // namespace tb
