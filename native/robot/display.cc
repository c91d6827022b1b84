#include "display.h"

#include <cerrno>
#include <cstring>
#include <exception>
#include <poll.h>
#include <thread>
#include <unistd.h>

#include "log.h"
#include "sched.h"
#include "wire.h"

namespace tb {

namespace {

void put_le(FILE* f, uint64_t v, int bytes) {
    uint8_t b[8];
    for (int i = 0; i < bytes; ++i) b[i] = static_cast<uint8_t>(v >> (8 * i));
    fwrite(b, 1, static_cast<size_t>(bytes), f);
}

}  // namespace

ReplayWriter::~ReplayWriter() {
    if (f_) fclose(f_);
}

bool ReplayWriter::open(const std::string& path, std::string& err) {
    f_ = fopen(path.c_str(), "wbe");
    if (!f_) err = path + ": " + strerror(errno);
    return f_ != nullptr;
}

void ReplayWriter::map(int origin, const uint8_t* payload, size_t n) {
    std::lock_guard<std::mutex> g(lock_);
    if (!f_) return;
    fputc('M', f_);
    put_le(f_, static_cast<uint64_t>(origin), 2);
    put_le(f_, n, 4);
    if (fwrite(payload, 1, n, f_) != n) failed_ = true;
}

void ReplayWriter::mark(char kind, uint32_t step) {
    std::lock_guard<std::mutex> g(lock_);
    if (!f_) return;
    fputc(kind, f_);
    put_le(f_, step, 4);
}

bool ReplayWriter::close() {
    std::lock_guard<std::mutex> g(lock_);
    if (!f_) return false;
    fputc('E', f_);
    bool ok = !failed_ && !ferror(f_);
    ok = fclose(f_) == 0 && ok;
    f_ = nullptr;
    return ok;
}

Display::Display(const Args& a, BodyClient& link, Flooder& flooder, EventLog& events,
                 ReplayWriter& replay)
    : a_(a), link_(link), flooder_(flooder), events_(events), replay_(replay),
      map_period_(std::max(1, a.map_period)),
      video_every_(std::max(1, a.video_every)) {}

void Display::run() {
    wake_pipe(wake_r_, wake_w_);  // none: the inbox notices the end within its poll's 0.5 s
    std::thread in(&Display::guarded_inbox, this);
    link_.ready();
    visualization();
    stopping = true;
    if (wake_w_.valid()) (void)!write(wake_w_.get(), "x", 1);
    in.join();
    wake_r_.reset();
    wake_w_.reset();
}

// An inbox that dies takes the display with it (exit status 3, as a robot's part), with its
// reason in the log, rather than std::terminate's abort.
void Display::guarded_inbox() {
    try {
        inbox();
    } catch (const std::exception& e) {
        LOG_ERROR("node.display", "the inbox part failed; the display stops: %s", e.what());
        _exit(3);
    }
}

// node.display._visualization: the frames of the steps it acts on (node.displaysteps).
void Display::visualization() {
    // Each frame is handled within two steps or counts as late (the fidelity verdict):
    // real-time priority like the robots' motion control, while the robots run.
    raise_priority(DEADLINE_RT, DEADLINE_NICE);
    BodyMsg msg;
    std::string err;
    while (!stopping) {
        int got = link_.recv(0.5, msg, err);
        if (got < 0) {  // as node/display.py: counted, dropped
            {
                std::lock_guard<std::mutex> g(counts_lock_);
                ++malformed_;
            }
            LOG_WARN("node.display", "dropped a malformed body message: %s", err.c_str());
            continue;
        }
        if (got == 0) continue;
        if (msg.kind == BodyKind::end) return;
        if (msg.kind != BodyKind::frame) continue;
        const Frame& f = msg.frame;
        int64_t step = f.step;
        step_ = step;
        if (step % map_period_ == 0) {
            uint32_t seq = flooder_.originate(KIND_BEACON, f.step, pack_beacon(f.x, f.y));
            events_.write("send", step, JsonObj().str("kind", "beacon").num("seq", seq));
        }
        if (step % video_every_ == 0 && !link_.pending()) replay_.mark('V', f.step);
        if (f.sent > 0) frame_lateness_.add((monotonic_s() - f.sent) * 1000 * a_.time_scale);
        if (a_.snapshots.count(step)) {
            replay_.mark('S', f.step);
            char name[32];
            snprintf(name, sizeof name, "step-%05lld.png", static_cast<long long>(step));
            events_.write("snapshot", step, JsonObj().str("file", name).boolean("final", false));
        }
    }
}

// node.display._inbox: every new map flood is merged (here: kept for the replay, in order).
void Display::inbox() {
    pollfd fds[2] = {{flooder_.fileno(), POLLIN, 0}, {wake_r_.get(), POLLIN, 0}};
    while (!stopping) {
        if (poll(fds, wake_r_.valid() ? 2 : 1, 500) <= 0 || !(fds[0].revents & POLLIN)) continue;
        for (const std::string& d : flooder_.receive_raw()) on_map_flood(d);
    }
}

void Display::on_map_flood(const std::string& data) {
    const uint8_t* d = reinterpret_cast<const uint8_t*>(data.data());
    FloodHeader h;
    std::string err;
    if (!unpack_flood(d, data.size(), h, err)) return;  // receive_raw let through only floods
    if (h.kind == KIND_BEACON) return;                   // another display's
    MapMsg m;
    if (h.kind != KIND_MAP) {
        err = "unexpected flood kind " + std::to_string(h.kind);
    } else if (unpack_map(d + h.payload_at, data.size() - h.payload_at, a_.rows, a_.cols, m,
                          err)) {
        replay_.map(h.origin, d + h.payload_at, data.size() - h.payload_at);
        {
            std::lock_guard<std::mutex> g(counts_lock_);
            received_.add("r" + std::to_string(h.origin));
        }
        events_.write("recv", step_, JsonObj().str("kind", "map").num("frm", h.origin)
                                         .num("sent", h.step));
        return;
    }
    {
        std::lock_guard<std::mutex> g(counts_lock_);
        ++malformed_;
    }
    LOG_WARN("node.display", "dropped a malformed flood: %s", err.c_str());
}

std::string Display::stepping_json() {
    std::lock_guard<std::mutex> g(counts_lock_);
    JsonObj lateness;
    lateness.raw("frame_done_ms", frame_lateness_.json());
    JsonObj o;
    o.num("step", step_).raw("received", received_.json_int()).num("malformed", malformed_);
    o.raw("flood", flooder_.counts_json()).raw("maps", flooder_.stats.json());
    o.raw("lateness", lateness.text());
    return o.text();
}

}  // namespace tb
