// The world's side of the robots' body links, each step's share of it in two calls: take every
// command the robots sent (sc_body_take) and send every robot its frame (sc_body_frames). The
// protocol is node/body.py's (docs/robot-contract.md); testbed/world/bodylink.py opens, accepts
// and names the sockets, handles every message that is not a command, and holds the Python
// twins these are tested against (tests/unit/test_body_fast.py): the same frames byte for byte,
// the same commands. Sockets are Unix SOCK_SEQPACKET: one datagram a message. Nothing here
// blocks: a robot whose socket is full misses its frame, as BodyServer.send has it.

#include <sys/socket.h>

#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstring>

#include "stepcore.h"

namespace {

constexpr size_t MAX_DATAGRAM = 65536;  // node.body.MAX_DATAGRAM
constexpr size_t CMD_SIZE = 14;         // 'C' u32 step u8 go f32 x f32 y
constexpr size_t FRAME_HEAD = 27;       // 'F' u32 step f32 x f32 y f32 theta f64 sent u16 n
constexpr size_t OTHER_HEAD = 8;        // u32 socket index, u32 length

uint32_t get_u32(const uint8_t* p) {
    return (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | (uint32_t)p[3];
}

void put_u32(uint8_t* p, uint32_t v) {
    p[0] = (uint8_t)(v >> 24);
    p[1] = (uint8_t)(v >> 16);
    p[2] = (uint8_t)(v >> 8);
    p[3] = (uint8_t)v;
}

float get_f32(const uint8_t* p) {
    const uint32_t bits = get_u32(p);
    float f;
    std::memcpy(&f, &bits, 4);
    return f;
}

void put_f32(uint8_t* p, float f) {
    uint32_t bits;
    std::memcpy(&bits, &f, 4);
    put_u32(p, bits);
}

void put_f64(uint8_t* p, double d) {
    uint64_t bits;
    std::memcpy(&bits, &d, 8);
    put_u32(p, (uint32_t)(bits >> 32));
    put_u32(p + 4, (uint32_t)bits);
}

}  // namespace

extern "C" {

// Read, without blocking, every datagram waiting on the sockets fds[0..n) (-1: no socket).
// A well-formed command (node.body.parse would give ("cmd", step, target)) is taken in place:
// taken[i] counts socket i's, step_out[i] is the largest step among them, and go_out[i] and
// xy_out[2i], xy_out[2i + 1] hold the last one's target (what BodyServer.poll's messages come
// to once RobotRecord.answered and World.command have taken each in turn). Any other datagram
// (a DONE, a HELLO, anything malformed) goes to `others` whole, after a header of the socket's
// index and its length (u32 each, host order), for the Python side to parse. hung[i] is 1 when
// socket i's peer hung up or the socket failed (it is read no further). The call stops reading
// when `others` could not take one more datagram of the largest size: what it leaves stays in
// the sockets for the next call. counts_out gets how many sockets had commands and how many
// hung up. Returns the bytes written to `others`, or -1 - that count when it stopped early.
int64_t sc_body_take(int n, const int32_t* fds, int32_t* taken, int64_t* step_out,
                     uint8_t* go_out, double* xy_out, uint8_t* hung, uint8_t* others,
                     int64_t others_cap, int32_t* counts_out) {
    static thread_local uint8_t buf[MAX_DATAGRAM];
    int64_t used = 0;
    counts_out[0] = counts_out[1] = 0;
    for (int i = 0; i < n; ++i) {
        taken[i] = 0;
        hung[i] = 0;
    }
    for (int i = 0; i < n; ++i) {
        if (fds[i] < 0) continue;
        for (;;) {
            if (others_cap - used < (int64_t)(OTHER_HEAD + MAX_DATAGRAM)) return -1 - used;
            const ssize_t got = recv(fds[i], buf, sizeof buf, MSG_DONTWAIT);
            if (got < 0 && errno == EINTR) continue;
            if (got < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) break;
            if (got <= 0) {  // an orderly hang-up, or the socket failed
                hung[i] = 1;
                ++counts_out[1];
                break;
            }
            if ((size_t)got == CMD_SIZE && buf[0] == 'C') {
                const int64_t step = get_u32(buf + 1);
                if (taken[i] == 0 || step > step_out[i]) step_out[i] = step;
                if (taken[i] == 0) ++counts_out[0];
                go_out[i] = buf[5] != 0;
                xy_out[2 * i] = buf[5] ? (double)get_f32(buf + 6) : 0.0;
                xy_out[2 * i + 1] = buf[5] ? (double)get_f32(buf + 10) : 0.0;
                ++taken[i];
                continue;
            }
            uint8_t* rec = others + used;
            std::memcpy(rec, &i, 4);
            const uint32_t len = (uint32_t)got;
            std::memcpy(rec + 4, &len, 4);
            std::memcpy(rec + OTHER_HEAD, buf, (size_t)got);
            used += (int64_t)(OTHER_HEAD + (size_t)got);
        }
    }
    return used;
}

// Send robot i (live[i], fds[i] >= 0) its frame of `step` (node.body.frame, byte for byte): pose
// from xyt (x, y, theta; metres and radians, rounded to float32 as struct's "f" rounds them), `sent`
// (CLOCK_MONOTONIC seconds), and its n_rays ranges: row i of `ranges` where has_ranges[i] is
// 1, else every ray +inf (a scan without returns). Without blocking. Returns how many frames
// were not sent (a socket full or failed), as BodyServer.send's False.
int sc_body_frames(int n, const int32_t* fds, const uint8_t* live, int64_t step,
                   const double* xyt, double sent, const float* ranges, const int8_t* has_ranges,
                   int n_rays) {
    static thread_local uint8_t buf[MAX_DATAGRAM];
    if (n_rays < 0 || FRAME_HEAD + 4 * (size_t)n_rays > sizeof buf) return n;
    const size_t size = FRAME_HEAD + 4 * (size_t)n_rays;
    int failed = 0;
    for (int i = 0; i < n; ++i) {
        if (!live[i] || fds[i] < 0) continue;
        buf[0] = 'F';
        put_u32(buf + 1, (uint32_t)step);
        put_f32(buf + 5, (float)xyt[3 * i]);
        put_f32(buf + 9, (float)xyt[3 * i + 1]);
        put_f32(buf + 13, (float)xyt[3 * i + 2]);
        put_f64(buf + 17, sent);
        buf[25] = (uint8_t)(n_rays >> 8);
        buf[26] = (uint8_t)n_rays;
        uint8_t* p = buf + FRAME_HEAD;
        if (has_ranges[i] == 1) {
            const float* row = ranges + (size_t)i * (size_t)n_rays;
            for (int j = 0; j < n_rays; ++j) put_f32(p + 4 * j, row[j]);
        } else {
            for (int j = 0; j < n_rays; ++j) put_f32(p + 4 * j, INFINITY);
        }
        ssize_t sent_bytes;
        do {
            sent_bytes = send(fds[i], buf, size, MSG_DONTWAIT | MSG_NOSIGNAL);
        } while (sent_bytes < 0 && errno == EINTR);
        if (sent_bytes != (ssize_t)size) ++failed;
    }
    return failed;
}

}  // extern "C"
