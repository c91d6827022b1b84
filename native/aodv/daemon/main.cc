// tb-aodv: the AODV (RFC 3561) routing daemon of one robot's network namespace, compiled;
// `python -m aodv`'s command line, kernel side, statistics file, exit statuses and signals
// around the C++ protocol core (native/aodv/core.cc). docs/aodv.md, "The compiled daemon".
//
// Exit statuses: 0 after SIGTERM or SIGINT; 2 for a usage error (the command line, the
// parameters, not root, a missing directory, a --netns it cannot enter, no such interface or
// no IPv4 address on it);
// 1 for any other failure at start-up.
#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <fcntl.h>
#include <sched.h>
#include <sys/stat.h>
#include <unistd.h>

#include "args.h"
#include "daemon.h"
#include "kernel.h"
#include "log.h"

namespace {
const char* NETNS_DIR = "/run/netns";  // where `ip netns` and topology/kernel/netns.py name them

int usage_error(const std::string& line) {
    fprintf(stderr, "tb-aodv: error: %s\n", line.c_str());
    return 2;
}

std::string parent_dir(const std::string& path) {
    std::string abs = path;
    if (abs.empty() || abs[0] != '/') {
        char cwd[4096];
        if (getcwd(cwd, sizeof cwd)) abs = std::string(cwd) + "/" + path;
    }
    size_t slash = abs.rfind('/');
    return slash == 0 ? "/" : abs.substr(0, slash);
}
}  // namespace

int main(int argc, char** argv) {
    // Signals wait, blocked in every thread, until the loop's ppoll lets them in: a SIGTERM
    // during start-up ends the daemon cleanly once it is up, everything undone.
    sigset_t block;
    sigemptyset(&block);
    sigaddset(&block, SIGTERM);
    sigaddset(&block, SIGINT);
    sigaddset(&block, SIGUSR1);
    sigprocmask(SIG_BLOCK, &block, nullptr);

    aodv::Args args;
    std::string error;
    bool help = false;
    if (!aodv::parse_args(argc, argv, args, error, help)) return usage_error(error);
    if (help) {
        fputs(aodv::usage_text().c_str(), stdout);
        return 0;
    }
    aodv::Params params;
    if (!aodv::build_params(args, params, error)) return usage_error(error);
    if (geteuid() != 0) return usage_error("needs root (CAP_NET_ADMIN) in the robot's namespace");
    for (auto [option, given, path] : {std::make_tuple("--stats", args.has_stats, args.stats),
                                       std::make_tuple("--state", args.has_state, args.state)}) {
        if (!given || path.empty()) continue;
        struct stat st {};
        std::string parent = parent_dir(path);
        if (stat(parent.c_str(), &st) != 0 || !S_ISDIR(st.st_mode))
            return usage_error(std::string("no directory for ") + option + ": " + parent);
    }
    if (!args.netns.empty()) {
        // Before any socket or thread: a socket belongs to the namespace it was made in, and
        // a thread starts in its creator's. Only the network namespace changes: the daemon
        // reads no /sys (interfaces by ioctl and rtnetlink, sysctls through /proc/sys/net,
        // which is the caller's namespace's), so it needs none of what `ip netns exec` adds.
        std::string path = std::string(NETNS_DIR) + "/" + args.netns;
        int fd = open(path.c_str(), O_RDONLY | O_CLOEXEC);
        int rc = fd < 0 ? -1 : setns(fd, CLONE_NEWNET);
        int e = errno;
        if (fd >= 0) close(fd);
        if (rc != 0) return usage_error("network namespace " + args.netns + ": " + strerror(e));
    }
    aodv::log::start(args.robot, args.log_level);
    int status;
    try {
        status = aodv::run_daemon(args, params);
    } catch (const aodv::KernelError& e) {
        std::string m = e.what();
        aodv::log::stop();
        fprintf(stderr, "tb-aodv: error: %s\n", m.c_str());
        return m.find("no interface") != std::string::npos ||
                       m.find("no IPv4") != std::string::npos
                   ? 2
                   : 1;
    } catch (const std::exception& e) {
        aodv::log::stop();
        fprintf(stderr, "tb-aodv: error: %s\n", e.what());
        return 1;
    }
    aodv::log::stop();
    return status;
}
