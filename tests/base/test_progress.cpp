// The progress line says only what it knows: never more than 100% (or more units than the
// phase's total) when work runs past an estimate, and no ETA while the phase is too young or
// too little of it is done to predict its end.
#include <gtest/gtest.h>

#include "base/progress.h"

using namespace catpaq;

namespace {

ProgressState state(uint64_t done, uint64_t total, double elapsed) {
    ProgressState s;
    s.task = "convert";
    s.phase = "clipping leaves";
    s.unit = "tri";
    s.done = done;
    s.total = total;
    s.elapsed = elapsed;
    return s;
}

}  // namespace

TEST(Progress, NamesTheTaskAndThePhase) {
    std::string line = format_progress_line(state(500, 1000, 1.0));
    EXPECT_EQ(line.rfind("convert: clipping leaves [", 0), 0u) << line;
    EXPECT_NE(line.find(" 50.0%"), std::string::npos) << line;
    EXPECT_NE(line.find("500/1.0k tri"), std::string::npos) << line;
}

TEST(Progress, NeverShowsMoreThanTheTotal) {
    std::string line = format_progress_line(state(1500, 1000, 10.0));
    EXPECT_NE(line.find("100.0%"), std::string::npos) << line;
    EXPECT_EQ(line.find("1.5k"), std::string::npos) << line;
    EXPECT_NE(line.find("1.0k/1.0k tri"), std::string::npos) << line;
    EXPECT_EQ(line.find("ETA"), std::string::npos) << "nothing left to estimate: " << line;
}

TEST(Progress, NoEtaUntilItMeansSomething) {
    // Too early in the phase, however much is done.
    EXPECT_EQ(format_progress_line(state(500, 1000, kEtaAfterSeconds * 0.5)).find("ETA"), std::string::npos);
    // Late enough, but too little done.
    EXPECT_EQ(format_progress_line(state(10, 1000, 30.0)).find("ETA"), std::string::npos);
    // Both: 250 of 1000 in 5 s, 750 more at 50/s.
    std::string line = format_progress_line(state(250, 1000, 5.0));
    EXPECT_NE(line.find("ETA 15.0 s"), std::string::npos) << line;
}

TEST(Progress, UnknownTotalsShowCountsWithoutBarOrEta) {
    std::string line = format_progress_line(state(4000, 0, 30.0));
    EXPECT_EQ(line.find('%'), std::string::npos) << line;
    EXPECT_EQ(line.find("ETA"), std::string::npos) << line;
    EXPECT_NE(line.find("4.0k tri"), std::string::npos) << line;
}

TEST(Progress, APhaseEndsWithItsCountTimeAndRate) {
    ProgressState s = state(2000000, 2000000, 4.0);
    s.finished = true;
    EXPECT_EQ(format_progress_line(s), "convert: clipping leaves: 2.0M tri in 4.0 s, 500.0k tri/s");
}
