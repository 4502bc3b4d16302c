#pragma once
// Private to the mesh module: whitespace tokenizing and strict number parsing for the text
// formats. Numbers use std::from_chars (no locale, no allocation) and must span the whole
// token, so "1.5abc" or "0x10" is rejected instead of being read as a prefix.
#include <charconv>
#include <cstdint>
#include <string>
#include <string_view>
#include <system_error>

namespace catpaq::mesh_io {

inline bool is_blank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v'; }

// Splits a line into whitespace-separated tokens.
class Tokens {
public:
    explicit Tokens(std::string_view line) : rest_(line) {}

    // The next token, or false when the line is exhausted.
    bool next(std::string_view& token) {
        size_t i = 0;
        while (i < rest_.size() && is_blank(rest_[i])) ++i;
        if (i == rest_.size()) {
            rest_ = {};
            return false;
        }
        size_t j = i;
        while (j < rest_.size() && !is_blank(rest_[j])) ++j;
        token = rest_.substr(i, j - i);
        rest_.remove_prefix(j);
        return true;
    }
    bool empty() {
        while (!rest_.empty() && is_blank(rest_.front())) rest_.remove_prefix(1);
        return rest_.empty();
    }
    std::string_view rest() const { return rest_; }

private:
    std::string_view rest_;
};

// Removes a '#' comment and surrounding blanks.
inline std::string_view strip_comment(std::string_view line) {
    size_t hash = line.find('#');
    if (hash != std::string_view::npos) line = line.substr(0, hash);
    while (!line.empty() && is_blank(line.back())) line.remove_suffix(1);
    while (!line.empty() && is_blank(line.front())) line.remove_prefix(1);
    return line;
}

// Parses a whole token as a double ("nan" and "inf" parse; callers check finiteness so those get
// a precise error). A leading '+' is accepted since some writers emit it.
inline bool parse_double(std::string_view token, double& out) {
    if (!token.empty() && token.front() == '+') token.remove_prefix(1);
    if (token.empty()) return false;
    auto [end, error] = std::from_chars(token.data(), token.data() + token.size(), out);
    return error == std::errc() && end == token.data() + token.size();
}

// As parse_double, rounding once, straight to float: a float written in shortest form reads back
// with the same bits (going through double could round twice).
inline bool parse_float(std::string_view token, float& out) {
    if (!token.empty() && token.front() == '+') token.remove_prefix(1);
    if (token.empty()) return false;
    auto [end, error] = std::from_chars(token.data(), token.data() + token.size(), out);
    return error == std::errc() && end == token.data() + token.size();
}

inline bool parse_int(std::string_view token, int64_t& out) {
    if (!token.empty() && token.front() == '+') token.remove_prefix(1);
    if (token.empty()) return false;
    auto [end, error] = std::from_chars(token.data(), token.data() + token.size(), out);
    return error == std::errc() && end == token.data() + token.size();
}

// A token quoted for an error message: at most 40 bytes, control bytes escaped.
inline std::string quoted(std::string_view token) {
    std::string out = "'";
    for (size_t i = 0; i < token.size() && i < 40; ++i) {
        unsigned char c = static_cast<unsigned char>(token[i]);
        if (c >= 32 && c < 127) {
            out += char(c);
        } else {
            static const char hex[] = "0123456789abcdef";
            out += "\\x";
            out += hex[c >> 4];
            out += hex[c & 15];
        }
    }
    if (token.size() > 40) out += "...";
    return out + "'";
}

// ASCII-lowercased copy (format keywords and file extensions are case-insensitive).
inline std::string lowercase(std::string_view s) {
    std::string out(s);
    for (char& c : out)
        if (c >= 'A' && c <= 'Z') c = char(c - 'A' + 'a');
    return out;
}

}  // namespace catpaq::mesh_io
