#include <gtest/gtest.h>

#include <filesystem>

#include "base/atomic_file.h"
#include "base/error.h"

using namespace catpaq;
namespace fs = std::filesystem;

static fs::path scratch(const char* name) {
    fs::path dir = fs::temp_directory_path() / ("catpaq_base_" + std::to_string(getpid()));
    fs::create_directories(dir);
    return dir / name;
}

TEST(AtomicFile, OutputAppearsOnlyAfterCommit) {
    fs::path path = scratch("a.bin");
    fs::remove(path);
    {
        AtomicFile file(path.string());
        file.write("hello", 5);
        EXPECT_FALSE(fs::exists(path));
        file.commit();
    }
    EXPECT_EQ(read_file(path.string()), "hello");
}

TEST(AtomicFile, AbandonedWriteLeavesNothingBehind) {
    fs::path path = scratch("b.bin");
    fs::remove(path);
    {
        AtomicFile file(path.string());
        file.write("partial", 7);
    }
    EXPECT_FALSE(fs::exists(path));
    for (auto& entry : fs::directory_iterator(path.parent_path()))
        EXPECT_EQ(entry.path().filename().string().find("b.bin.tmp"), std::string::npos);
}

TEST(AtomicFile, UnwritableDirectoryIsAClearError) {
    try {
        AtomicFile file("/nonexistent_dir_catpaq/x.bin");
        FAIL() << "expected an error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("/nonexistent_dir_catpaq/x.bin"), std::string::npos);
    }
}
