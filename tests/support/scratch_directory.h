#pragma once
// A test process's scratch directory: temp_directory_path()/PREFIX<pid>[SUFFIX], created empty on
// construction and removed with everything in it on destruction. ctest runs every test in a
// process of its own, so a directory that outlives its process is never used again: it used to
// leave hundreds of them (over 1 GB) in /tmp per run.
//
// Set CATPAQ_KEEP_SCRATCH (any value) to keep the directories, to inspect what a failing test wrote.
//
// Usually held in a function-local static, so that it is made on first use and removed at exit;
// one object per name and process (a second one would empty the first's directory).
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <string>
#include <system_error>

namespace catpaq::test {

class ScratchDirectory {
public:
    explicit ScratchDirectory(const std::string& prefix, const std::string& suffix = "")
        : path_(std::filesystem::temp_directory_path() / (prefix + std::to_string(::getpid()) + suffix)),
          owner_(::getpid()) {
        // A directory of this name is a leftover of an earlier process with the same pid
        // (kept, or killed): start empty.
        std::filesystem::remove_all(path_);
        std::filesystem::create_directories(path_);
    }
    ~ScratchDirectory() {
        // Only the creating process removes it: a forked child that exits normally (a death
        // test, say) runs this destructor too, while its parent still uses the directory.
        if (::getpid() != owner_ || keep_ || std::getenv("CATPAQ_KEEP_SCRATCH")) return;
        std::error_code ignored;  // a destructor at exit must not throw; a leftover is harmless
        std::filesystem::remove_all(path_, ignored);
    }
    ScratchDirectory(const ScratchDirectory&) = delete;
    ScratchDirectory& operator=(const ScratchDirectory&) = delete;

    const std::filesystem::path& path() const { return path_; }
    std::string string() const { return path_.string(); }
    std::filesystem::path operator/(const std::string& name) const { return path_ / name; }

    // Leaves the directory in place at the end (e.g. for images saved to be looked at).
    void keep() { keep_ = true; }

private:
    std::filesystem::path path_;
    pid_t owner_;
    bool keep_ = false;
};

}  // namespace catpaq::test
