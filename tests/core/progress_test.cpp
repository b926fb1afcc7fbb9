// Build progress (core/progress.h): reports reach the sink with the work done, an ETA and a last
// report per stage; stages nest; advances from many threads all count; the interval limits the
// reports. (`gimlod build`'s bar and lines: tests/cli/build_progress_cli_test.cpp.)
#include <gtest/gtest.h>

#include <mutex>
#include <thread>
#include <vector>

#include "core/progress.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

struct Captured {
  std::mutex mutex;
  std::vector<progress::Report> reports;
  void install(double interval) {
    progress::setSink(
        [this](const progress::Report& r) {
          std::lock_guard<std::mutex> lock(mutex);
          reports.push_back(r);
        },
        interval);
  }
  ~Captured() { progress::setSink({}, 0.0); }
};

TEST(Progress, ReportsWorkDoneWithAnEtaAndAFinalReport) {
  Captured c;
  c.install(0.0);
  {
    const progress::ProgressStage stage("charts", 10);
    for (int i = 0; i < 10; ++i) progress::advance();
  }
  ASSERT_GE(c.reports.size(), 2u);
  uint64_t last = 0;
  for (const progress::Report& r : c.reports) {
    EXPECT_EQ(r.stage, "charts");
    EXPECT_EQ(r.total, 10u);
    EXPECT_GE(r.done, last);
    last = r.done;
  }
  // The ETA is unknown before any work is done, then the time left at the rate so far: the time
  // taken and the ETA add up to the whole stage at that rate; the final report has none left.
  for (const progress::Report& r : c.reports) {
    if (r.finished) {
      EXPECT_EQ(r.etaSeconds, 0.0);
    } else if (r.done == 0) {
      EXPECT_LT(r.etaSeconds, 0.0);
    } else {
      EXPECT_GE(r.etaSeconds, 0.0);
      EXPECT_NEAR(r.seconds + r.etaSeconds, r.seconds * double(r.total) / double(r.done), 1e-9 + 1e-12 * r.seconds);
    }
  }
  EXPECT_FALSE(c.reports.front().finished);
  EXPECT_TRUE(c.reports.back().finished);
  EXPECT_EQ(c.reports.back().done, 10u);
}

TEST(Progress, StagesNestAndAdvancesFromManyThreadsAllCount) {
  Captured c;
  c.install(1e9);  // only the stages' last reports
  {
    const progress::ProgressStage outer("outer", 5);
    progress::advance(2);
    {
      const progress::ProgressStage inner("inner", 4000);
      std::vector<std::thread> threads;
      for (int t = 0; t < 4; ++t)
        threads.emplace_back([] {
          for (int i = 0; i < 1000; ++i) progress::advance();
        });
      for (auto& t : threads) t.join();
    }
    progress::advance(3);
  }
  progress::advance(7);  // no stage: nothing
  ASSERT_EQ(c.reports.size(), 2u);
  EXPECT_EQ(c.reports[0].stage, "inner");
  EXPECT_EQ(c.reports[0].done, 4000u);
  EXPECT_EQ(c.reports[1].stage, "outer");
  EXPECT_EQ(c.reports[1].done, 5u);
}

TEST(Progress, FormatsABarAPercentageAndTheEta) {
  progress::Report r;
  r.stage = "charts";
  r.done = 45;
  r.total = 100;
  r.seconds = 90.0;
  r.etaSeconds = 110.0;
  const std::string s = progress::format(r, 20);
  EXPECT_NE(s.find("charts [#########...........]"), std::string::npos) << s;
  EXPECT_NE(s.find(" 45% 45/100"), std::string::npos) << s;
  EXPECT_NE(s.find("1m30s"), std::string::npos) << s;
  EXPECT_NE(s.find("ETA 1m50s"), std::string::npos) << s;
  r.finished = true;
  EXPECT_NE(progress::format(r, 0).find("done"), std::string::npos);
}

}  // namespace
}  // namespace gimlod
