// A small strict JSON reader and writer: the goal and re-plan messages (node.wire) and the
// event log's lines (node.events). The reader takes what node.wire's decoder takes
// (docs/robot-contract.md, section 3): Python's json.loads of a strict UTF-8 text (RFC 8259,
// plus NaN, Infinity and -Infinity, which a validator then refuses where a number must be
// finite), with two limits: an integer outside int64 is refused, and so is a text nesting
// more than 64 objects and arrays one inside another. The writer writes what
// json.dumps(separators=(",", ":")) writes: floats as Python's repr (shortest round trip),
// non-ASCII escaped.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace tb {

struct Json {
    enum Kind { NUL, BOOL, INT, REAL, STR, ARR, OBJ } kind = NUL;
    bool b = false;
    int64_t i = 0;
    double d = 0;
    std::string s;
    std::vector<Json> arr;
    std::vector<std::pair<std::string, Json>> obj;  // in order; a repeated key: the last wins

    const Json* get(const std::string& key) const;
    bool is_number() const { return kind == INT || kind == REAL || kind == BOOL; }
    double number() const {
        return kind == INT ? static_cast<double>(i) : kind == BOOL ? (b ? 1 : 0) : d;
    }
};

// Parses `text` into `out`; false (and why in `err`) when it is not one JSON value.
bool json_parse(const std::string& text, Json& out, std::string& err);

// Python's repr of a float (json.dumps writes the same; NaN and infinities as JSON's extension).
std::string py_float(double v);
// Python's round(v, digits) for a float: the nearest double to the correctly rounded decimal.
double py_round(double v, int digits);
// A JSON string literal of `s`, ASCII out (the event log's strings are ASCII; any other byte
// is written as \u00XX).
std::string json_quote(const std::string& s);

// Builds one JSON object text field by field, as json.dumps(..., separators=(",", ":")).
class JsonObj {
public:
    JsonObj& raw(const std::string& key, const std::string& json_text);
    JsonObj& str(const std::string& key, const std::string& v) { return raw(key, json_quote(v)); }
    JsonObj& num(const std::string& key, int64_t v) { return raw(key, std::to_string(v)); }
    JsonObj& real(const std::string& key, double v) { return raw(key, py_float(v)); }
    JsonObj& boolean(const std::string& key, bool v) { return raw(key, v ? "true" : "false"); }
    JsonObj& null(const std::string& key) { return raw(key, "null"); }
    std::string text() const { return "{" + body_ + "}"; }

private:
    std::string body_;
};

}  // namespace tb
