// The compiled AODV daemon of one robot: start-up and teardown, and the loop that turns IO
// into events of the protocol core (the twin of aodv/daemon.py).
#pragma once

#include <string>

#include "../params.h"
#include "args.h"

namespace aodv {

// Runs until SIGTERM or SIGINT; 0 then. A start-up failure is a KernelError (what() is the
// line to print), after what was made is undone.
int run_daemon(const Args& args, const Params& params);

}  // namespace aodv
