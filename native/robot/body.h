// The robot's link to its body (node/body.py; docs/robot-contract.md): a Unix SOCK_SEQPACKET
// socket to the world, one datagram per message, network byte order.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "fd.h"

namespace tb {

struct Frame {
    uint32_t step = 0;
    double x = 0, y = 0, theta = 0;  // float32 on the wire, widened as Python does
    double sent = 0;                 // the world's time.monotonic() when it sent the frame
    std::vector<float> ranges;
};

// A body message's kind: node.body.parse's first item.
enum class BodyKind { hello, frame, end, cmd, done };
const char* body_kind_name(BodyKind k);  // "hello", "frame", ... (node.body's names)

// One decoded body message.
struct BodyMsg {
    BodyKind kind = BodyKind::end;
    Frame frame;                 // frame
    uint32_t step = 0;           // cmd, done
    int robot = 0, role = 0;     // hello
    bool go = false;             // cmd
    double tx = 0, ty = 0;       // cmd target
};

// Decodes one datagram as node.body.parse does; false (and why) when it is malformed (a FRAME
// whose x, y, theta or sent is not finite is).
bool body_parse(const uint8_t* data, size_t n, BodyMsg& out, std::string& err);
// node.body.check_frame: false (and why) unless the frame's position is on a map of width_m x
// height_m metres (0 <= x < width, 0 <= y < height) and it has n_rays ranges.
bool body_check_frame(const Frame& f, double width_m, double height_m, int n_rays,
                      std::string& err);
// tb-robot --decode frame WIDTHxHEIGHT RAYS (selftest.cc): body_parse, then body_check_frame,
// of the bytes `in`; prints "ok" or "refused: <why>" (status 0 or 1).
int body_frame_selftest(const std::vector<std::string>& argv, const std::string& in);
std::string body_hello(int robot, int role);
std::string body_cmd(uint32_t step, bool go, double x, double y);
std::string body_done(uint32_t step);
std::string body_frame(const Frame& f);

// The robot side: one reader thread (motion control), any writer.
class BodyClient {
public:
    BodyClient() = default;
    BodyClient(const BodyClient&) = delete;
    BodyClient& operator=(const BodyClient&) = delete;
    // `role`: 0 a robot, 1 the display (node.body.ROLE_ROBOT, ROLE_DISPLAY).
    bool open(const std::string& path, int robot, std::string& err, int role = 0);
    void ready();  // HELLO: every part is running
    // From now on recv refuses (-1) a frame body_check_frame refuses (node.body's expect).
    void expect(double width_m, double height_m, int n_rays);
    // 1: a message in `out`; 0: timeout; -1: malformed (why in err). The world hanging up
    // comes as kind "end".
    int recv(double timeout_s, BodyMsg& out, std::string& err);
    bool pending();
    void send(const std::string& data);

private:
    Fd fd_;
    int robot_ = 0, role_ = 0;
    bool bounded_ = false;  // expect() was called
    double width_m_ = 0, height_m_ = 0;
    int n_rays_ = 0;
    std::vector<uint8_t> buf_ = std::vector<uint8_t>(65536);
};

}  // namespace tb
