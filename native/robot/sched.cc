#include "sched.h"

#include <cstdlib>
#include <cstring>
#include <sched.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

namespace tb {

std::string raise_priority(int rt_priority, int nice) {
    const char* rt = getenv("TESTBED_REALTIME");
    if (!(rt && strcmp(rt, "0") == 0)) {
        sched_param p{};
        p.sched_priority = rt_priority;
        // pid 0: the calling thread (Linux schedules threads), as os.sched_setscheduler(0).
        if (sched_setscheduler(0, SCHED_RR | SCHED_RESET_ON_FORK, &p) == 0)
            return "SCHED_RR " + std::to_string(rt_priority);
    }
    // setpriority(PRIO_PROCESS, 0) on Linux sets the calling thread's nice.
    if (setpriority(PRIO_PROCESS, (id_t)syscall(SYS_gettid), nice) == 0)
        return "nice " + std::to_string(nice);
    return "normal";
}

}  // namespace tb
