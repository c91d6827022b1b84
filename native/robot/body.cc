#include "body.h"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include "json.h"
#include "robot_consts.h"
#include "wirebytes.h"

namespace tb {

namespace {
constexpr size_t HELLO = gen::BODY_HELLO, FRAME = gen::BODY_FRAME, CMD = gen::BODY_CMD,
                 DONE = gen::BODY_DONE;
}

const char* body_kind_name(BodyKind k) {
    switch (k) {
        case BodyKind::hello: return "hello";
        case BodyKind::frame: return "frame";
        case BodyKind::end: return "end";
        case BodyKind::cmd: return "cmd";
        case BodyKind::done: return "done";
    }
    return "?";
}

bool body_parse(const uint8_t* d, size_t n, BodyMsg& out, std::string& err) {
    if (n == 0) {
        err = "empty body message";
        return false;
    }
    out = BodyMsg();
    switch (d[0]) {
        case 'H':
            if (n != HELLO) break;
            out.kind = BodyKind::hello;
            out.robot = rd16(d + 1);
            out.role = d[3];
            return true;
        case 'F': {
            if (n < FRAME) break;
            out.kind = BodyKind::frame;
            Frame& f = out.frame;
            f.step = rd32(d + 1);
            f.x = rdf32(d + 5);
            f.y = rdf32(d + 9);
            f.theta = rdf32(d + 13);
            f.sent = rdf64(d + 17);
            size_t rays = rd16(d + 25);
            if (n - FRAME != 4 * rays) {
                err = "frame length does not match its ray count";
                return false;
            }
            if (!std::isfinite(f.x) || !std::isfinite(f.y) || !std::isfinite(f.theta) ||
                !std::isfinite(f.sent)) {
                err = "frame with a position, heading or time that is not finite";
                return false;
            }
            f.ranges.resize(rays);
            for (size_t k = 0; k < rays; ++k) f.ranges[k] = rdf32(d + FRAME + 4 * k);
            return true;
        }
        case 'E':
            out.kind = BodyKind::end;  // as node.body: the first byte decides
            return true;
        case 'C':
            if (n != CMD) break;
            out.kind = BodyKind::cmd;
            out.step = rd32(d + 1);
            out.go = d[5] != 0;
            out.tx = rdf32(d + 6);
            out.ty = rdf32(d + 10);
            return true;
        case 'D':
            if (n != DONE) break;
            out.kind = BodyKind::done;
            out.step = rd32(d + 1);
            return true;
        default:
            err = "unknown body message type";
            return false;
    }
    err = "malformed body message: wrong length";
    return false;
}

bool body_check_frame(const Frame& f, double width_m, double height_m, int n_rays,
                      std::string& err) {
    if (!(f.x >= 0.0 && f.x < width_m && f.y >= 0.0 && f.y < height_m)) {
        err = "frame position (" + py_float(f.x) + ", " + py_float(f.y) + ") is off the map";
        return false;
    }
    if (static_cast<int64_t>(f.ranges.size()) != n_rays) {
        err = "frame has " + std::to_string(f.ranges.size()) + " ranges, the laser " +
              std::to_string(n_rays);
        return false;
    }
    return true;
}

int body_frame_selftest(const std::vector<std::string>& argv, const std::string& in) {
    double w = 0, h = 0;
    char* end = nullptr;
    long rays = argv.size() == 4 ? strtol(argv[3].c_str(), &end, 10) : -1;
    if (argv.size() != 4 || sscanf(argv[2].c_str(), "%lfx%lf", &w, &h) != 2 || *end ||
        rays < 0 || rays > 65535) {
        fprintf(stderr, "node: --decode frame WIDTHxHEIGHT RAYS (metres, a count)\n");
        return 2;
    }
    BodyMsg m;
    std::string err;
    bool ok = body_parse(reinterpret_cast<const uint8_t*>(in.data()), in.size(), m, err);
    if (ok && m.kind != BodyKind::frame) {
        ok = false;
        err = "not a frame";
    }
    if (ok) ok = body_check_frame(m.frame, w, h, static_cast<int>(rays), err);
    if (ok) {
        printf("ok\n");
        return 0;
    }
    printf("refused: %s\n", err.c_str());
    return 1;
}

std::string body_hello(int robot, int role) {
    std::string o = "H";
    put16(o, static_cast<uint16_t>(robot));
    put8(o, static_cast<uint8_t>(role));
    return o;
}

std::string body_cmd(uint32_t step, bool go, double x, double y) {
    std::string o = "C";
    put32(o, step);
    put8(o, go ? 1 : 0);
    putf32(o, go ? static_cast<float>(x) : 0.0f);
    putf32(o, go ? static_cast<float>(y) : 0.0f);
    return o;
}

std::string body_done(uint32_t step) {
    std::string o = "D";
    put32(o, step);
    return o;
}

std::string body_frame(const Frame& f) {
    std::string o = "F";
    put32(o, f.step);
    putf32(o, static_cast<float>(f.x));
    putf32(o, static_cast<float>(f.y));
    putf32(o, static_cast<float>(f.theta));
    putf64(o, f.sent);
    put16(o, static_cast<uint16_t>(f.ranges.size()));
    for (float r : f.ranges) putf32(o, r);
    return o;
}

bool BodyClient::open(const std::string& path, int robot, std::string& err, int role) {
    robot_ = robot;
    role_ = role;
    fd_.reset(socket(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0));
    if (!fd_.valid()) {
        err = std::string("body link: ") + strerror(errno);
        return false;
    }
    sockaddr_un a{};
    a.sun_family = AF_UNIX;
    if (path.size() >= sizeof a.sun_path) {
        err = "body link: socket path too long";
        return false;
    }
    memcpy(a.sun_path, path.c_str(), path.size() + 1);
    if (connect(fd_.get(), reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
        err = "body link " + path + ": " + strerror(errno);
        return false;
    }
    return true;
}

void BodyClient::ready() { send(body_hello(robot_, role_)); }

void BodyClient::expect(double width_m, double height_m, int n_rays) {
    bounded_ = true;
    width_m_ = width_m;
    height_m_ = height_m;
    n_rays_ = n_rays;
}

int BodyClient::recv(double timeout_s, BodyMsg& out, std::string& err) {
    pollfd p{fd_.get(), POLLIN, 0};
    int r = poll(&p, 1, static_cast<int>(timeout_s * 1000));
    if (r == 0 || (r < 0 && errno == EINTR)) return 0;
    ssize_t n = ::recv(fd_.get(), buf_.data(), buf_.size(), 0);
    if (n <= 0) {
        out = BodyMsg();
        out.kind = BodyKind::end;
        return 1;
    }
    if (!body_parse(buf_.data(), static_cast<size_t>(n), out, err)) return -1;
    if (bounded_ && out.kind == BodyKind::frame &&
        !body_check_frame(out.frame, width_m_, height_m_, n_rays_, err))
        return -1;
    return 1;
}

bool BodyClient::pending() {
    pollfd p{fd_.get(), POLLIN, 0};
    return poll(&p, 1, 0) > 0;
}

void BodyClient::send(const std::string& data) {
    // The world gone: the reader sees the hang-up.
    (void)::send(fd_.get(), data.data(), data.size(), MSG_NOSIGNAL);
}

}  // namespace tb
