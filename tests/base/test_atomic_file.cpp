#include <gtest/gtest.h>

#include <filesystem>

#include "base/atomic_file.h"
#include "base/error.h"
#include "scratch_directory.h"

using namespace catpaq;
namespace fs = std::filesystem;

static fs::path scratch(const char* name) {
    static const catpaq::test::ScratchDirectory dir("catpaq_base_");
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

// While it is written, the file has no name at all (O_TMPFILE): however the process ends, no
// temporary is left next to the output.
TEST(AtomicFile, NothingIsNamedUntilCommit) {
    fs::path path = scratch("c.bin");
    fs::remove(path);
    AtomicFile file(path.string());
    file.write("data", 4);
    if (!file.anonymous()) GTEST_SKIP() << "no O_TMPFILE on this file system";
    for (auto& entry : fs::directory_iterator(path.parent_path()))
        EXPECT_EQ(entry.path().filename().string().find("c.bin"), std::string::npos) << entry.path();
    file.commit();
    EXPECT_EQ(read_file(path.string()), "data");
}

TEST(AtomicFile, CommitReplacesAnExistingFileWholly) {
    fs::path path = scratch("d.bin");
    write_file_atomic(path.string(), "old contents", 12);
    {
        AtomicFile file(path.string());
        file.write("new", 3);
        EXPECT_EQ(read_file(path.string()), "old contents");
        file.commit();
    }
    EXPECT_EQ(read_file(path.string()), "new");
    for (auto& entry : fs::directory_iterator(path.parent_path()))
        EXPECT_EQ(entry.path().filename().string().find("d.bin.tmp"), std::string::npos) << entry.path();
}

TEST(AtomicFile, ADirectoryIsRefusedByName) {
    fs::path dir = scratch("e_dir");
    fs::create_directories(dir);
    try {
        AtomicFile file(dir.string());
        FAIL() << "expected an error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find(dir.string() + "' is a directory"), std::string::npos) << e.what();
    }
}
