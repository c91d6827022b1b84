// JSON as the Python daemon writes it (json.dumps with sort_keys): objects with their keys
// sorted, floats as Python's repr (the shortest text that reads back as the same double),
// strings ASCII with \u escapes; compact (separators "," and ":") or indented by one space
// (common.jsonfile.write_json_atomic). Plus the one atomic write (a temporary file renamed
// over the old one, as common.jsonfile.write_atomic) and a small strict reader for the
// counter file.
#pragma once

#include <map>
#include <memory>
#include <string>
#include <vector>

namespace aodv::json {

struct Value {
    enum Type { Null, Bool, Int, Real, Str, Arr, Obj } t = Null;
    bool b = false;
    long long i = 0;
    double d = 0;
    std::string s;
    std::vector<Value> arr;
    std::map<std::string, Value> obj;  // sorted keys, as sort_keys=True

    Value() = default;
    static Value boolean(bool v) { Value x; x.t = Bool; x.b = v; return x; }
    static Value integer(long long v) { Value x; x.t = Int; x.i = v; return x; }
    static Value real(double v) { Value x; x.t = Real; x.d = v; return x; }
    static Value str(std::string v) { Value x; x.t = Str; x.s = std::move(v); return x; }
    static Value array() { Value x; x.t = Arr; return x; }
    static Value object() { Value x; x.t = Obj; return x; }
    Value& operator[](const std::string& k) { t = Obj; return obj[k]; }
    const Value* get(const std::string& k) const;
};

// Python's repr(float): "0.0", "1.5", "1e-05", "1e+16", "inf", "nan".
std::string py_repr(double x);
// Python's round(x, n) for the few digits the statistics keep.
double py_round(double x, int n);
// The text of `v`: compact, or indented by `indent` spaces a level (json.dumps(indent=1)).
std::string dump(const Value& v, int indent = -1);
// Strict JSON (what json.loads takes without NaN); false on anything else.
bool parse(const std::string& text, Value& out);

// `path` holds `data` or what it held before, never a part; errno-style message on failure.
bool write_atomic(const std::string& path, const std::string& data, std::string* err);

}  // namespace aodv::json
