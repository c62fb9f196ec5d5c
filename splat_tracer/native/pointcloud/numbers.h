// Tables of decimal numbers in text (ASCII PLY, ASCII PCD, XYZ/PTS/CSV): whitespace-separated
// tokens parsed to float64 on all cores, with each line's count of tokens, so that the
// readers find a row of the wrong length (or a token that is not a number) by its line.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <vector>

namespace splat {

// One piece of the text, cut at a line boundary, parsed on its own.
struct NumberChunk {
    const char *begin = nullptr, *end = nullptr;
    std::vector<double> values;     // every token in order; NaN where one is not a number
    std::vector<int64_t> per_line;  // tokens on each line of the chunk
    std::vector<int64_t> bad_lines; // the chunk's lines (from its first, 0) holding a token that is not a number
};

// The whole text's table: the chunks in order (their lines and values follow one another).
struct NumberTable {
    std::vector<NumberChunk> chunks;
    size_t values() const;
    size_t lines() const;
    size_t bad_lines() const;
    // Copies into caller buffers of values(), lines() and bad_lines() elements; bad lines
    // are numbered over the whole text (from 0).
    void copy(double *values, int64_t *per_line, int64_t *bad_lines, int threads) const;
};

// Parses `size` bytes of text. Whitespace is what C's isspace() and numpy's parser take in
// the C locale: space, \t, \n, \v, \f, \r; a line ends at \n (a last line without one counts
// when it is not empty). A token is a number when Python's float() reads it, less its
// underscores and non-ASCII digits (which numpy refuses too): an optional sign, then digits
// with an optional '.', '.5', '5.', an optional exponent, or inf, infinity, nan (any case).
// The value is the correctly rounded float64 (std::from_chars), the same as float()'s and
// numpy's; beyond the range of float64 it is +-inf, below it +-0 (as strtod and numpy);
// 'nan' with either sign is numpy's positive quiet NaN. Any other token (a NUL, a non-ASCII
// byte, '1,5', 'nan(1)', a 1 GB run of digits followed by an 'x') is not a number: its line
// is listed, never a crash. The text is cut into pieces of about `chunk_bytes` at line
// boundaries, parsed on `threads` workers (0: all cores); the result does not depend on
// either. Returns false when keep_going() said stop (polled between pieces).
bool parse_number_table(const char *data, size_t size, size_t chunk_bytes, int threads,
                        const std::function<bool()> &keep_going, NumberTable &out);

// One token [begin, end) (no whitespace inside), as parse_number_table reads it; false when
// it is not a number.
bool parse_number(const char *begin, const char *end, double &out);

}  // namespace splat
