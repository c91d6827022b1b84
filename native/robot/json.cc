#include "json.h"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "robot_consts.h"

namespace tb {

const Json* Json::get(const std::string& key) const {
    const Json* hit = nullptr;
    for (const auto& kv : obj)
        if (kv.first == key) hit = &kv.second;
    return hit;
}

namespace {

// Objects and arrays one inside another, at most (node.wire.MAX_DEPTH): a text nesting
// deeper is refused where its 65th opens, before any recursion past it.
using gen::MAX_DEPTH;

struct Reader {
    const std::string& t;
    size_t p = 0;
    std::string err;

    bool fail(const char* why) {
        if (err.empty()) err = std::string(why) + " at byte " + std::to_string(p);
        return false;
    }
    void ws() {
        while (p < t.size() && (t[p] == ' ' || t[p] == '\t' || t[p] == '\n' || t[p] == '\r')) ++p;
    }
    bool lit(const char* word) {
        size_t n = strlen(word);
        if (t.compare(p, n, word) != 0) return false;
        p += n;
        return true;
    }
    static void put_utf8(std::string& o, uint32_t cp) {
        if (cp < 0x80) {
            o += static_cast<char>(cp);
        } else if (cp < 0x800) {
            o += static_cast<char>(0xC0 | (cp >> 6));
            o += static_cast<char>(0x80 | (cp & 0x3F));
        } else if (cp < 0x10000) {
            o += static_cast<char>(0xE0 | (cp >> 12));
            o += static_cast<char>(0x80 | ((cp >> 6) & 0x3F));
            o += static_cast<char>(0x80 | (cp & 0x3F));
        } else {
            o += static_cast<char>(0xF0 | (cp >> 18));
            o += static_cast<char>(0x80 | ((cp >> 12) & 0x3F));
            o += static_cast<char>(0x80 | ((cp >> 6) & 0x3F));
            o += static_cast<char>(0x80 | (cp & 0x3F));
        }
    }
    bool hex4(uint32_t& v) {
        if (p + 4 > t.size()) return fail("short \\u escape");
        v = 0;
        for (int k = 0; k < 4; ++k) {
            char c = t[p++];
            v <<= 4;
            if (c >= '0' && c <= '9') v |= c - '0';
            else if (c >= 'a' && c <= 'f') v |= c - 'a' + 10;
            else if (c >= 'A' && c <= 'F') v |= c - 'A' + 10;
            else return fail("bad \\u escape");
        }
        return true;
    }
    // One UTF-8 sequence starting at p, copied to o; false when it is not valid UTF-8.
    bool utf8(std::string& o) {
        unsigned char c = t[p];
        int n = c >= 0xF0 && c <= 0xF4 ? 3 : c >= 0xE0 ? 2 : c >= 0xC2 && c < 0xE0 ? 1 : -1;
        if (c >= 0xF5 || n < 0) return fail("not UTF-8");
        if (p + n >= t.size()) return fail("truncated UTF-8");
        uint32_t cp = c & (0x3F >> n);
        for (int k = 1; k <= n; ++k) {
            unsigned char d = t[p + k];
            if ((d & 0xC0) != 0x80) return fail("not UTF-8");
            cp = (cp << 6) | (d & 0x3F);
        }
        if ((n == 2 && cp < 0x800) || (n == 3 && (cp < 0x10000 || cp > 0x10FFFF)) ||
            (cp >= 0xD800 && cp <= 0xDFFF))
            return fail("not UTF-8");
        o.append(t, p, n + 1);
        p += n + 1;
        return true;
    }
    bool string(std::string& o) {
        ++p;  // the opening quote
        while (true) {
            if (p >= t.size()) return fail("unterminated string");
            unsigned char c = t[p];
            if (c == '"') {
                ++p;
                return true;
            }
            if (c < 0x20) return fail("control character in string");
            if (c == '\\') {
                if (++p >= t.size()) return fail("unterminated string");
                char e = t[p++];
                switch (e) {
                    case '"': o += '"'; break;
                    case '\\': o += '\\'; break;
                    case '/': o += '/'; break;
                    case 'b': o += '\b'; break;
                    case 'f': o += '\f'; break;
                    case 'n': o += '\n'; break;
                    case 'r': o += '\r'; break;
                    case 't': o += '\t'; break;
                    case 'u': {
                        uint32_t v = 0;
                        if (!hex4(v)) return false;
                        // A surrogate pair joins; a lone surrogate is kept (as Python does).
                        if (v >= 0xD800 && v < 0xDC00 && t.compare(p, 2, "\\u") == 0) {
                            size_t keep = p;
                            p += 2;
                            uint32_t lo = 0;
                            if (hex4(lo) && lo >= 0xDC00 && lo <= 0xDFFF) {
                                v = 0x10000 + ((v - 0xD800) << 10) + (lo - 0xDC00);
                            } else {
                                err.clear();
                                p = keep;
                            }
                        }
                        put_utf8(o, v);
                        break;
                    }
                    default: return fail("bad escape");
                }
                continue;
            }
            if (c < 0x80) {
                o += static_cast<char>(c);
                ++p;
            } else if (!utf8(o)) {
                return false;
            }
        }
    }
    bool number(Json& v) {
        size_t s = p;
        if (t[p] == '-') ++p;
        if (p < t.size() && t.compare(p, 8, "Infinity") == 0) {
            p += 8;
            v.kind = Json::REAL;
            v.d = -INFINITY;
            return true;
        }
        if (p >= t.size() || !isdigit((unsigned char)t[p])) return fail("bad number");
        if (t[p] == '0') ++p;
        else while (p < t.size() && isdigit((unsigned char)t[p])) ++p;
        bool real = false;
        if (p < t.size() && t[p] == '.') {
            real = true;
            ++p;
            if (p >= t.size() || !isdigit((unsigned char)t[p])) return fail("bad fraction");
            while (p < t.size() && isdigit((unsigned char)t[p])) ++p;
        }
        if (p < t.size() && (t[p] == 'e' || t[p] == 'E')) {
            real = true;
            ++p;
            if (p < t.size() && (t[p] == '+' || t[p] == '-')) ++p;
            if (p >= t.size() || !isdigit((unsigned char)t[p])) return fail("bad exponent");
            while (p < t.size() && isdigit((unsigned char)t[p])) ++p;
        }
        std::string text = t.substr(s, p - s);
        if (real) {
            v.kind = Json::REAL;
            v.d = strtod(text.c_str(), nullptr);
            return true;
        }
        v.kind = Json::INT;
        auto r = std::from_chars(text.data(), text.data() + text.size(), v.i);
        if (r.ec != std::errc()) return fail("integer out of range");
        return true;
    }
    // One value; `depth` counts the objects and arrays around it.
    bool value(Json& v, int depth) {
        ws();
        if (p >= t.size()) return fail("expected a value");
        char c = t[p];
        if ((c == '{' || c == '[') && depth >= MAX_DEPTH) return fail("nested too deep");
        if (c == '{') {
            v.kind = Json::OBJ;
            ++p;
            ws();
            if (p < t.size() && t[p] == '}') {
                ++p;
                return true;
            }
            while (true) {
                ws();
                if (p >= t.size() || t[p] != '"') return fail("expected a key");
                std::string key;
                if (!string(key)) return false;
                ws();
                if (p >= t.size() || t[p] != ':') return fail("expected ':'");
                ++p;
                Json item;
                if (!value(item, depth + 1)) return false;
                v.obj.emplace_back(std::move(key), std::move(item));
                ws();
                if (p < t.size() && t[p] == ',') {
                    ++p;
                    continue;
                }
                if (p < t.size() && t[p] == '}') {
                    ++p;
                    return true;
                }
                return fail("expected ',' or '}'");
            }
        }
        if (c == '[') {
            v.kind = Json::ARR;
            ++p;
            ws();
            if (p < t.size() && t[p] == ']') {
                ++p;
                return true;
            }
            while (true) {
                Json item;
                if (!value(item, depth + 1)) return false;
                v.arr.push_back(std::move(item));
                ws();
                if (p < t.size() && t[p] == ',') {
                    ++p;
                    continue;
                }
                if (p < t.size() && t[p] == ']') {
                    ++p;
                    return true;
                }
                return fail("expected ',' or ']'");
            }
        }
        if (c == '"') {
            v.kind = Json::STR;
            return string(v.s);
        }
        if (lit("true")) {
            v.kind = Json::BOOL;
            v.b = true;
            return true;
        }
        if (lit("false")) {
            v.kind = Json::BOOL;
            return true;
        }
        if (lit("null")) return true;
        if (lit("NaN")) {
            v.kind = Json::REAL;
            v.d = NAN;
            return true;
        }
        if (lit("Infinity")) {
            v.kind = Json::REAL;
            v.d = INFINITY;
            return true;
        }
        if (c == '-' || isdigit((unsigned char)c)) return number(v);
        return fail("unexpected character");
    }
};

}  // namespace

bool json_parse(const std::string& text, Json& out, std::string& err) {
    Reader r{text, 0, {}};
    out = Json();
    // A UTF-8 byte order mark is not JSON (Python refuses it too).
    bool ok = r.value(out, 0);
    if (ok) {
        r.ws();
        if (r.p != text.size()) ok = r.fail("extra data after the value");
    }
    if (!ok) err = r.err;
    return ok;
}

std::string py_float(double v) {
    if (std::isnan(v)) return "NaN";
    if (std::isinf(v)) return v > 0 ? "Infinity" : "-Infinity";
    char buf[64];
    auto r = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::scientific);
    std::string sci(buf, r.ptr);  // "-d.ddde+XX"
    size_t e = sci.find('e');
    int exp10 = atoi(sci.c_str() + e + 1);
    if (exp10 < -4 || exp10 >= 16) return sci;
    std::string mant = sci.substr(0, e);
    bool neg = mant[0] == '-';
    std::string digits;
    for (char c : mant)
        if (isdigit((unsigned char)c)) digits += c;
    std::string out = neg ? "-" : "";
    if (exp10 >= 0) {
        size_t ip = static_cast<size_t>(exp10) + 1;
        if (digits.size() <= ip) {
            out += digits + std::string(ip - digits.size(), '0') + ".0";
        } else {
            out += digits.substr(0, ip) + "." + digits.substr(ip);
        }
    } else {
        out += "0." + std::string(static_cast<size_t>(-exp10 - 1), '0') + digits;
    }
    return out;
}

double py_round(double v, int digits) {
    if (!std::isfinite(v)) return v;
    char buf[400];
    snprintf(buf, sizeof buf, "%.*f", digits, v);
    return strtod(buf, nullptr);
}

std::string json_quote(const std::string& s) {
    std::string o = "\"";
    for (size_t i = 0; i < s.size(); ++i) {
        unsigned char c = s[i];
        char esc[8];
        switch (c) {
            case '"': o += "\\\""; break;
            case '\\': o += "\\\\"; break;
            case '\n': o += "\\n"; break;
            case '\r': o += "\\r"; break;
            case '\t': o += "\\t"; break;
            case '\b': o += "\\b"; break;
            case '\f': o += "\\f"; break;
            default:
                if (c < 0x20 || c >= 0x80) {
                    snprintf(esc, sizeof esc, "\\u%04x", c);
                    o += esc;
                } else {
                    o += static_cast<char>(c);
                }
        }
    }
    return o + "\"";
}

JsonObj& JsonObj::raw(const std::string& key, const std::string& json_text) {
    if (!body_.empty()) body_ += ",";
    body_ += json_quote(key) + ":" + json_text;
    return *this;
}

}  // namespace tb
