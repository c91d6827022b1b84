// See json.h.
#include "json.h"

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fcntl.h>
#include <random>
#include <sys/stat.h>
#include <unistd.h>

namespace aodv::json {

const Value* Value::get(const std::string& k) const {
    if (t != Obj) return nullptr;
    auto it = obj.find(k);
    return it == obj.end() ? nullptr : &it->second;
}

std::string py_repr(double x) {
    if (std::isnan(x)) return "NaN";  // json.dumps spells them so
    if (std::isinf(x)) return x > 0 ? "Infinity" : "-Infinity";
    if (x == 0) return std::signbit(x) ? "-0.0" : "0.0";
    // The shortest digits that read back as x (to_chars' shortest round trip, as Python's
    // repr), in scientific form: its digits and exponent.
    char buf[64];
    auto res = std::to_chars(buf, buf + sizeof buf, x, std::chars_format::scientific);
    std::string s(buf, res.ptr);
    bool neg = s[0] == '-';
    if (neg) s.erase(0, 1);
    size_t e = s.find('e');
    int exp = atoi(s.c_str() + e + 1);
    std::string digits;
    for (size_t k = 0; k < e; ++k)
        if (s[k] != '.') digits += s[k];
    while (digits.size() > 1 && digits.back() == '0') digits.pop_back();
    std::string out;
    // float_repr_style 'short': scientific when the exponent is < -4 or >= 16.
    if (exp < -4 || exp >= 16) {
        out = digits.substr(0, 1);
        if (digits.size() > 1) out += "." + digits.substr(1);
        char eb[16];
        snprintf(eb, sizeof eb, "e%c%02d", exp < 0 ? '-' : '+', exp < 0 ? -exp : exp);
        out += eb;
    } else if (exp < 0) {
        out = "0." + std::string(size_t(-exp - 1), '0') + digits;
    } else if (size_t(exp) + 1 >= digits.size()) {
        out = digits + std::string(size_t(exp) + 1 - digits.size(), '0') + ".0";
    } else {
        out = digits.substr(0, size_t(exp) + 1) + "." + digits.substr(size_t(exp) + 1);
    }
    return neg ? "-" + out : out;
}

double py_round(double x, int n) {
    if (!std::isfinite(x)) return x;
    // Through the decimal text at n digits (correctly rounded from the exact value, as
    // Python's round does), read back.
    char buf[400];
    auto res = std::to_chars(buf, buf + sizeof buf, x, std::chars_format::fixed, n);
    double out = x;
    std::from_chars(buf, res.ptr, out);
    return out;
}

namespace {
void quote(const std::string& s, std::string& out) {
    out += '"';
    size_t k = 0;
    auto u = [&out](unsigned cp) {
        char b[8];
        snprintf(b, sizeof b, "\\u%04x", cp);
        out += b;
    };
    while (k < s.size()) {
        unsigned char c = (unsigned char)s[k];
        if (c == '"') out += "\\\"";
        else if (c == '\\') out += "\\\\";
        else if (c == '\n') out += "\\n";
        else if (c == '\r') out += "\\r";
        else if (c == '\t') out += "\\t";
        else if (c == '\b') out += "\\b";
        else if (c == '\f') out += "\\f";
        else if (c < 0x20) u(c);
        else if (c < 0x80) out += char(c);
        else {
            // UTF-8 to \u escapes (ensure_ascii); a byte that is not UTF-8 as Python's
            // surrogateescape reads it from argv (U+DC80 + byte).
            int len = c >= 0xF0 && c < 0xF8 ? 4 : c >= 0xE0 ? 3 : c >= 0xC2 && c < 0xE0 ? 2 : 0;
            unsigned cp = len == 4 ? c & 7 : len == 3 ? c & 15 : c & 31;
            bool ok = len > 0 && k + size_t(len) <= s.size();
            for (int j = 1; ok && j < len; ++j) {
                unsigned char d = (unsigned char)s[k + size_t(j)];
                if ((d & 0xC0) != 0x80) ok = false;
                cp = (cp << 6) | (d & 0x3F);
            }
            if (ok && (cp > 0x10FFFF || (cp >= 0xD800 && cp < 0xE000) ||
                       (len == 3 && cp < 0x800) || (len == 4 && cp < 0x10000)))
                ok = false;
            if (!ok) {
                u(0xDC00 + c);
                ++k;
                continue;
            }
            if (cp >= 0x10000) {
                cp -= 0x10000;
                u(0xD800 + (cp >> 10));
                u(0xDC00 + (cp & 0x3FF));
            } else {
                u(cp);
            }
            k += size_t(len);
            continue;
        }
        ++k;
    }
    out += '"';
}

void dump_to(const Value& v, int indent, int depth, std::string& out) {
    auto newline = [&](int d) {
        out += '\n';
        out.append(size_t(indent * d), ' ');
    };
    switch (v.t) {
        case Value::Null: out += "null"; break;
        case Value::Bool: out += v.b ? "true" : "false"; break;
        case Value::Int: out += std::to_string(v.i); break;
        case Value::Real: out += py_repr(v.d); break;
        case Value::Str: quote(v.s, out); break;
        case Value::Arr:
            if (v.arr.empty()) { out += "[]"; break; }
            out += '[';
            for (size_t k = 0; k < v.arr.size(); ++k) {
                if (k) out += indent >= 0 ? "," : (",");
                if (indent >= 0) newline(depth + 1);
                dump_to(v.arr[k], indent, depth + 1, out);
            }
            if (indent >= 0) newline(depth);
            out += ']';
            break;
        case Value::Obj: {
            if (v.obj.empty()) { out += "{}"; break; }
            out += '{';
            bool first = true;
            for (const auto& [k, x] : v.obj) {
                if (!first) out += ',';
                first = false;
                if (indent >= 0) newline(depth + 1);
                quote(k, out);
                out += indent >= 0 ? ": " : ":";
                dump_to(x, indent, depth + 1, out);
            }
            if (indent >= 0) newline(depth);
            out += '}';
            break;
        }
    }
}

struct Parser {
    const std::string& s;
    size_t k = 0;
    int depth = 0;
    void ws() {
        while (k < s.size() && (s[k] == ' ' || s[k] == '\t' || s[k] == '\n' || s[k] == '\r')) ++k;
    }
    bool lit(const char* w) {
        size_t n = strlen(w);
        if (s.compare(k, n, w) != 0) return false;
        k += n;
        return true;
    }
    bool value(Value& v) {
        if (++depth > 64) return false;
        ws();
        bool ok = value_inner(v);
        --depth;
        return ok;
    }
    bool value_inner(Value& v) {
        if (k >= s.size()) return false;
        char c = s[k];
        if (c == '{') {
            v = Value::object();
            ++k;
            ws();
            if (k < s.size() && s[k] == '}') { ++k; return true; }
            for (;;) {
                ws();
                Value key;
                if (k >= s.size() || s[k] != '"' || !string(key.s)) return false;
                ws();
                if (k >= s.size() || s[k] != ':') return false;
                ++k;
                Value x;
                if (!value(x)) return false;
                v.obj[key.s] = std::move(x);
                ws();
                if (k < s.size() && s[k] == ',') { ++k; continue; }
                if (k < s.size() && s[k] == '}') { ++k; return true; }
                return false;
            }
        }
        if (c == '[') {
            v = Value::array();
            ++k;
            ws();
            if (k < s.size() && s[k] == ']') { ++k; return true; }
            for (;;) {
                Value x;
                if (!value(x)) return false;
                v.arr.push_back(std::move(x));
                ws();
                if (k < s.size() && s[k] == ',') { ++k; continue; }
                if (k < s.size() && s[k] == ']') { ++k; return true; }
                return false;
            }
        }
        if (c == '"') { v.t = Value::Str; return string(v.s); }
        if (lit("true")) { v = Value::boolean(true); return true; }
        if (lit("false")) { v = Value::boolean(false); return true; }
        if (lit("null")) { v = Value(); return true; }
        return number(v);
    }
    bool string(std::string& out) {
        ++k;
        while (k < s.size()) {
            char c = s[k++];
            if (c == '"') return true;
            if ((unsigned char)c < 0x20) return false;
            if (c != '\\') { out += c; continue; }
            if (k >= s.size()) return false;
            char e = s[k++];
            switch (e) {
                case '"': out += '"'; break;
                case '\\': out += '\\'; break;
                case '/': out += '/'; break;
                case 'b': out += '\b'; break;
                case 'f': out += '\f'; break;
                case 'n': out += '\n'; break;
                case 'r': out += '\r'; break;
                case 't': out += '\t'; break;
                case 'u':
                    if (k + 4 > s.size()) return false;
                    for (int j = 0; j < 4; ++j)
                        if (!isxdigit((unsigned char)s[k + size_t(j)])) return false;
                    k += 4;
                    out += '?';  // the counter file holds no such string
                    break;
                default: return false;
            }
        }
        return false;
    }
    bool number(Value& v) {
        size_t start = k;
        if (k < s.size() && s[k] == '-') ++k;
        if (k >= s.size() || !isdigit((unsigned char)s[k])) return false;
        if (s[k] == '0') ++k;
        else while (k < s.size() && isdigit((unsigned char)s[k])) ++k;
        bool real = false;
        if (k < s.size() && s[k] == '.') {
            real = true;
            ++k;
            if (k >= s.size() || !isdigit((unsigned char)s[k])) return false;
            while (k < s.size() && isdigit((unsigned char)s[k])) ++k;
        }
        if (k < s.size() && (s[k] == 'e' || s[k] == 'E')) {
            real = true;
            ++k;
            if (k < s.size() && (s[k] == '+' || s[k] == '-')) ++k;
            if (k >= s.size() || !isdigit((unsigned char)s[k])) return false;
            while (k < s.size() && isdigit((unsigned char)s[k])) ++k;
        }
        std::string text = s.substr(start, k - start);
        if (!real) {
            errno = 0;
            long long x = strtoll(text.c_str(), nullptr, 10);
            if (errno == 0) { v = Value::integer(x); return true; }
        }
        v = Value::real(strtod(text.c_str(), nullptr));
        return true;
    }
};
}  // namespace

std::string dump(const Value& v, int indent) {
    std::string out;
    dump_to(v, indent, 0, out);
    return out;
}

bool parse(const std::string& text, Value& out) {
    Parser p{text};
    if (!p.value(out)) return false;
    p.ws();
    return p.k == text.size();
}

bool write_atomic(const std::string& path, const std::string& data, std::string* err) {
    auto fail = [&](const std::string& what) {
        if (err) *err = what + ": " + strerror(errno);
        return false;
    };
    size_t slash = path.rfind('/');
    std::string dir = slash == std::string::npos ? "." : slash == 0 ? "/" : path.substr(0, slash);
    std::string name = slash == std::string::npos ? path : path.substr(slash + 1);
    int dfd = open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (dfd < 0) return fail(dir);
    struct stat st {};
    if (fstatat(dfd, name.c_str(), &st, AT_SYMLINK_NOFOLLOW) == 0 && S_ISDIR(st.st_mode)) {
        close(dfd);
        errno = EISDIR;
        return fail(path);
    }
    static thread_local std::mt19937 rng{std::random_device{}()};
    char tmp[512];
    snprintf(tmp, sizeof tmp, ".%s.%d.%08x.tmp", name.c_str(), int(getpid()), unsigned(rng()));
    int fd = openat(dfd, tmp, O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0644);
    if (fd < 0) {
        bool r = fail(path);
        close(dfd);
        return r;
    }
    fchmod(fd, 0644);
    size_t off = 0;
    while (off < data.size()) {
        ssize_t n = ::write(fd, data.data() + off, data.size() - off);
        if (n < 0) {
            if (errno == EINTR) continue;
            bool r = fail(path);
            close(fd);
            unlinkat(dfd, tmp, 0);
            close(dfd);
            return r;
        }
        off += size_t(n);
    }
    if (close(fd) != 0 || renameat(dfd, tmp, dfd, name.c_str()) != 0) {
        bool r = fail(path);
        unlinkat(dfd, tmp, 0);
        close(dfd);
        return r;
    }
    close(dfd);
    return true;
}

}  // namespace aodv::json
