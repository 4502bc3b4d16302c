#pragma once
// Helpers for the mesh tests: a per-process scratch directory, small file writers, and an
// assertion that reading a file fails with a message naming the file and the problem.
#include <gtest/gtest.h>

#include <bit>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <string>
#include <unistd.h>

#include "base/error.h"
#include "mesh/io.h"
#include "scratch_directory.h"

namespace catpaq::test {

inline std::string scratch(const std::string& name) {
    static const ScratchDirectory dir("catpaq_mesh_");
    return (dir / name).string();
}

// Writes `content` (text or raw bytes) to a scratch file and returns its path.
inline std::string write_file(const std::string& name, const std::string& content) {
    std::string path = scratch(name);
    std::ofstream out(path, std::ios::binary);
    out.write(content.data(), std::streamsize(content.size()));
    return path;
}

// Passes if `read` throws catpaq::Error whose message contains `path` and every one of `words`.
template <class Read>
::testing::AssertionResult fails_with(Read read, const std::string& path, std::initializer_list<const char*> words) {
    try {
        read();
    } catch (const Error& e) {
        std::string message = e.what();
        if (message.find(path) == std::string::npos)
            return ::testing::AssertionFailure() << "message does not name '" << path << "': " << message;
        for (const char* word : words)
            if (message.find(word) == std::string::npos)
                return ::testing::AssertionFailure() << "message lacks '" << word << "': " << message;
        return ::testing::AssertionSuccess() << message;
    } catch (const std::exception& e) {
        return ::testing::AssertionFailure() << "threw a non-catpaq exception: " << e.what();
    }
    return ::testing::AssertionFailure() << "no error reading " << path;
}

inline ::testing::AssertionResult read_fails(const std::string& path, std::initializer_list<const char*> words) {
    return fails_with([&] { read_mesh(path); }, path, words);
}

// Little helpers to assemble binary files by hand (put_le copies host bytes).
static_assert(std::endian::native == std::endian::little, "the tests assume a little-endian host");
template <class T>
void put_le(std::string& out, T value) {
    char bytes[sizeof(T)];
    std::memcpy(bytes, &value, sizeof(T));
    out.append(bytes, sizeof(T));
}
template <class T>
void put_be(std::string& out, T value) {
    char bytes[sizeof(T)];
    std::memcpy(bytes, &value, sizeof(T));
    for (size_t i = sizeof(T); i-- > 0;) out.push_back(bytes[i]);
}

}  // namespace catpaq::test
