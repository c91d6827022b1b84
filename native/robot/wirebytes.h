// Network byte order readers and writers for the body link and the floods.
#pragma once

#include <cstdint>
#include <cstring>
#include <string>

namespace tb {

inline uint16_t rd16(const uint8_t* p) { return static_cast<uint16_t>(p[0] << 8 | p[1]); }
inline uint32_t rd32(const uint8_t* p) {
    return static_cast<uint32_t>(p[0]) << 24 | static_cast<uint32_t>(p[1]) << 16 |
           static_cast<uint32_t>(p[2]) << 8 | p[3];
}
inline float rdf32(const uint8_t* p) {
    uint32_t u = rd32(p);
    float f;
    memcpy(&f, &u, 4);
    return f;
}
inline double rdf64(const uint8_t* p) {
    uint64_t u = (uint64_t)rd32(p) << 32 | rd32(p + 4);
    double d;
    memcpy(&d, &u, 8);
    return d;
}
inline void put8(std::string& o, uint8_t v) { o += static_cast<char>(v); }
inline void put16(std::string& o, uint16_t v) {
    o += static_cast<char>(v >> 8);
    o += static_cast<char>(v);
}
inline void put32(std::string& o, uint32_t v) {
    put16(o, static_cast<uint16_t>(v >> 16));
    put16(o, static_cast<uint16_t>(v));
}
inline void putf32(std::string& o, float f) {
    uint32_t u;
    memcpy(&u, &f, 4);
    put32(o, u);
}
inline void putf64(std::string& o, double d) {
    uint64_t u;
    memcpy(&u, &d, 8);
    put32(o, static_cast<uint32_t>(u >> 32));
    put32(o, static_cast<uint32_t>(u));
}

}  // namespace tb
