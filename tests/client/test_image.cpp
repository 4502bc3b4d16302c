// PNG output: exact round trip, atomic writes, clear errors.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "base/error.h"
#include "client/image.h"
#include "gl_support.h"

using namespace catpaq;

TEST(Png, RoundTripIsExact) {
    const int w = 37, h = 23;  // odd sizes: no row padding assumptions
    std::vector<uint8_t> rgba(size_t(w) * h * 4);
    for (size_t i = 0; i < rgba.size(); ++i) rgba[i] = uint8_t((i * 131 + i / 7) & 0xff);
    std::string path = test::scratch_dir() + "/round_trip.png";
    write_png(path, w, h, rgba);
    RgbaImage back = read_png(path);
    EXPECT_EQ(back.width, w);
    EXPECT_EQ(back.height, h);
    EXPECT_EQ(back.rgba, rgba);
    // Nothing but the output is left behind (the temporary was renamed).
    size_t files = 0;
    for (auto& e : std::filesystem::directory_iterator(test::scratch_dir()))
        files += e.path().filename().string().find("round_trip") != std::string::npos;
    EXPECT_EQ(files, 1u);
}

TEST(Png, RejectsBadInputClearly) {
    std::string dir = test::scratch_dir();
    EXPECT_THROW(write_png(dir + "/bad.png", 4, 4, std::vector<uint8_t>(10)), Error);
    EXPECT_THROW(write_png(dir + "/bad.png", 0, 4, {}), Error);
    EXPECT_FALSE(std::filesystem::exists(dir + "/bad.png"));
    EXPECT_THROW(write_png(dir + "/no/such/dir/x.png", 1, 1, std::vector<uint8_t>(4)), Error);
    {
        std::ofstream out(dir + "/not.png");
        out << "definitely not a png";
    }
    try {
        read_png(dir + "/not.png");
        ADD_FAILURE() << "read a non-PNG";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("not.png"), std::string::npos) << e.what();
    }
    EXPECT_THROW(read_png(dir + "/missing.png"), Error);
}
