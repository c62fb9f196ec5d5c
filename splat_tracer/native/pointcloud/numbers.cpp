#include "pointcloud/numbers.h"

#include <algorithm>
#include <charconv>
#include <cstring>
#include <limits>
#include <system_error>

#include "base/parallel.h"

namespace splat {
namespace {

// numpy's whitespace (C isspace in the C locale): space, \t \n \v \f \r.
inline bool is_space(char c) { return c == ' ' || static_cast<unsigned char>(c - '\t') <= '\r' - '\t'; }
inline bool is_digit(char c) { return static_cast<unsigned char>(c - '0') <= 9; }

// [begin, end) equals `word` (lower case) in any case.
bool equal_nocase(const char *begin, const char *end, const char *word) {
    const size_t n = std::strlen(word);
    if (size_t(end - begin) != n) return false;
    for (size_t i = 0; i < n; ++i)
        if ((begin[i] | 0x20) != word[i]) return false;
    return true;
}

// For a decimal number (no sign) that from_chars read whole but found beyond float64's range:
// whether its magnitude is at least 1 (an overflow: inf) rather than below 1 (an underflow:
// 0). float64 overflows from 1.8e308 and underflows below 2.5e-324, so the sign of the
// decimal exponent of the first significant digit tells which; that exponent is counted
// here in int64 however many digits the token has (a written exponent of any length
// saturates, far beyond either limit).
bool at_least_one(const char *p, const char *end) {
    int64_t whole = 0, zeros = 0;  // significant digits before the point; zeros after it before the first other digit
    bool point = false, significant = false;
    for (; p < end && (is_digit(*p) || *p == '.'); ++p) {
        if (*p == '.') {
            point = true;
        } else if (!point) {
            significant |= *p != '0';
            whole += significant;
        } else if (!significant) {
            if (*p != '0') significant = true;
            else ++zeros;
        }
    }
    int64_t exponent = 0;
    if (p < end && (*p == 'e' || *p == 'E')) {
        ++p;
        const bool negative = p < end && *p == '-';
        if (p < end && (*p == '-' || *p == '+')) ++p;
        constexpr int64_t kSaturate = int64_t(1) << 50;  // beyond any token's digit count
        for (; p < end && is_digit(*p); ++p) exponent = std::min(kSaturate, exponent * 10 + (*p - '0'));
        if (negative) exponent = -exponent;
    }
    const int64_t first = whole > 0 ? whole - 1 : -(zeros + 1);
    return first + exponent >= 0;
}

// Splits [data, data + size) into pieces of about `chunk_bytes`, each ending just after a
// newline (the last at the end of the text): no line is cut.
std::vector<NumberChunk> cut(const char *data, size_t size, size_t chunk_bytes) {
    std::vector<NumberChunk> chunks;
    const char *p = data, *end = data + size;
    while (p < end) {
        const char *stop = end;
        if (size_t(end - p) > chunk_bytes) {
            const void *nl = std::memchr(p + chunk_bytes, '\n', size_t(end - (p + chunk_bytes)));
            if (nl) stop = static_cast<const char *>(nl) + 1;
        }
        NumberChunk c;
        c.begin = p, c.end = stop;
        chunks.push_back(std::move(c));
        p = stop;
    }
    return chunks;
}

// Parses the token that starts at p (not whitespace) into `out`; returns where the parse
// stopped: at the token's end when it is a number, before it otherwise. One pass over the
// digits (from_chars finds the token's end itself).
inline const char *parse_prefix(const char *p, const char *end, double &out) {
    const char *s = p;
    const bool negative = *s == '-';
    if (*s == '-' || *s == '+') ++s;
    if (s < end && (is_digit(*s) || *s == '.')) {  // from_chars would take another sign, or inf/nan(...)
        const std::from_chars_result r = std::from_chars(s, end, out, std::chars_format::general);
        if (r.ec == std::errc::result_out_of_range)
            out = at_least_one(s, r.ptr) ? std::numeric_limits<double>::infinity() : 0.0;
        else if (r.ec != std::errc())
            return p;
        out = negative ? -out : out;
        return r.ptr;
    }
    const char *q = s;
    while (q < end && !is_space(*q)) ++q;
    if (equal_nocase(s, q, "inf") || equal_nocase(s, q, "infinity")) {
        out = negative ? -std::numeric_limits<double>::infinity() : std::numeric_limits<double>::infinity();
        return q;
    }
    if (equal_nocase(s, q, "nan")) {
        out = std::numeric_limits<double>::quiet_NaN();  // numpy's, whatever the sign
        return q;
    }
    return p;
}

void parse_chunk(NumberChunk &c) {
    // A typical token and its separator take 8 to 20 bytes: a first guess, grown as needed.
    c.values.reserve(size_t(c.end - c.begin) / 8 + 1);
    const char *p = c.begin, *end = c.end;
    int64_t line = 0, on_line = 0;
    bool bad = false;
    while (p < end) {
        const char ch = *p;
        if (ch == '\n') {
            c.per_line.push_back(on_line);
            if (bad) c.bad_lines.push_back(line);
            ++line, on_line = 0, bad = false, ++p;
            continue;
        }
        if (is_space(ch)) {
            ++p;
            continue;
        }
        double v;
        const char *q = parse_prefix(p, end, v);
        if (q == p || (q < end && !is_space(*q))) {  // not a number, or more follows it: '1x', '1,5'
            v = std::numeric_limits<double>::quiet_NaN(), bad = true;
            for (q = p + 1; q < end && !is_space(*q);) ++q;
        }
        c.values.push_back(v);
        ++on_line;
        p = q;
    }
    if (c.end > c.begin && c.end[-1] != '\n') {  // the text's last line, without its newline
        c.per_line.push_back(on_line);
        if (bad) c.bad_lines.push_back(line);
    }
}

}  // namespace

bool parse_number(const char *p, const char *end, double &out) {
    return p < end && !is_space(*p) && parse_prefix(p, end, out) == end;
}

size_t NumberTable::values() const {
    size_t n = 0;
    for (const NumberChunk &c : chunks) n += c.values.size();
    return n;
}

size_t NumberTable::lines() const {
    size_t n = 0;
    for (const NumberChunk &c : chunks) n += c.per_line.size();
    return n;
}

size_t NumberTable::bad_lines() const {
    size_t n = 0;
    for (const NumberChunk &c : chunks) n += c.bad_lines.size();
    return n;
}

void NumberTable::copy(double *values, int64_t *per_line, int64_t *bad_lines, int threads) const {
    std::vector<size_t> at_value(chunks.size()), at_line(chunks.size()), at_bad(chunks.size());
    size_t v = 0, l = 0, b = 0;
    for (size_t i = 0; i < chunks.size(); ++i) {
        at_value[i] = v, at_line[i] = l, at_bad[i] = b;
        v += chunks[i].values.size(), l += chunks[i].per_line.size(), b += chunks[i].bad_lines.size();
    }
    parallel_for(
        chunks.size(), threads,
        [&](size_t i) {
            const NumberChunk &c = chunks[i];
            std::copy(c.values.begin(), c.values.end(), values + at_value[i]);
            std::copy(c.per_line.begin(), c.per_line.end(), per_line + at_line[i]);
            for (size_t k = 0; k < c.bad_lines.size(); ++k)
                bad_lines[at_bad[i] + k] = c.bad_lines[k] + int64_t(at_line[i]);  // numbered over the whole text
        },
        [](size_t) { return true; });
}

bool parse_number_table(const char *data, size_t size, size_t chunk_bytes, int threads,
                        const std::function<bool()> &keep_going, NumberTable &out) {
    out.chunks = cut(data, size, std::max<size_t>(chunk_bytes, 1));
    return parallel_for(
        out.chunks.size(), threads, [&](size_t i) { parse_chunk(out.chunks[i]); },
        [&](size_t) { return keep_going(); });
}

}  // namespace splat
