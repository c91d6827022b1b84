// The display role in C++ (node/display.py is the reference): a mesh member with no body that
// relays floods like a robot, takes the robots' maps, floods a beacon every map period and
// keeps what the video and the snapshots will show. It does the part of the display that
// runs while the robots step; what is drawn is drawn after they stopped, in Python, from a
// replay this part writes (node/displayreplay.py: the maps as they came, in order, and the
// steps at which a video frame or a snapshot was kept). The two together write what the
// Python display writes: events.jsonl, map.npy, the snapshots and the video.
#pragma once

#include <atomic>
#include <cstdint>
#include <cstdio>
#include <mutex>
#include <string>

#include "args.h"
#include "body.h"
#include "events.h"
#include "fd.h"
#include "flood.h"
#include "stats.h"

namespace tb {

// The replay's records (little-endian): 'M' u16 origin, u32 length, the map payload as it
// came; 'V' u32 step (a video frame kept); 'S' u32 step (a snapshot). The file ends with
// 'E' when the display stopped in order.
class ReplayWriter {
public:
    ~ReplayWriter();
    bool open(const std::string& path, std::string& err);
    void map(int origin, const uint8_t* payload, size_t n);
    void mark(char kind, uint32_t step);
    bool close();  // 'E', flushed; false when a write failed

private:
    std::mutex lock_;  // guards f_ (the inbox writes maps, visualization its marks)
    FILE* f_ = nullptr;
    bool failed_ = false;
};

class Display {
public:
    Display(const Args& a, BodyClient& link, Flooder& flooder, EventLog& events,
            ReplayWriter& replay);
    void run();  // until the world ends the run (or `stopping`)
    // The part of the summary event this process knows (node.displayreplay adds the rest).
    std::string stepping_json();
    std::atomic<bool> stopping{false};

private:
    // The inbox thread shares with visualization (the calling thread) only what is guarded:
    // the flooder (its cache, counts and map stats under their locks; its receive buffer
    // the inbox's alone, its sequence number visualization's alone), the replay and the event
    // log (each under its lock), received_ and malformed_ (counts_lock_), step_ and stopping
    // (atomics); a_ is read only and the wake pipe is made before the thread starts.
    void guarded_inbox();
    void inbox();
    void visualization();
    void on_map_flood(const std::string& data);

    const Args& a_;
    BodyClient& link_;
    Flooder& flooder_;
    EventLog& events_;
    ReplayWriter& replay_;
    int map_period_, video_every_;
    std::atomic<int64_t> step_{-1};
    Fd wake_r_, wake_w_;  // run()'s end wakes the inbox's poll
    std::mutex counts_lock_;  // guards received_ and malformed_ (inbox), read at the end
    Counter received_;
    int64_t malformed_ = 0;
    Lateness frame_lateness_{MS_BOUNDS};  // visualization's alone
};

}  // namespace tb
