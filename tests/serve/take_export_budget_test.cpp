// TakeExportBudget: what finished exports may hold, in total and per peer address
// (docs/reliability.md, "Export memory").
#include "serve/take_export_budget.hpp"

#include <gtest/gtest.h>

#include <string>

namespace mocap::serve {
namespace {

TEST(TakeExportBudget, ACallerIsRefusedPastItsAddressesShareAndTheOthersAreNot) {
    TakeExportBudget budget(100, 60);
    std::string why;
    auto a1 = budget.try_charge("10.0.0.1", 40, &why);
    ASSERT_NE(a1, nullptr) << why;
    EXPECT_EQ(budget.try_charge("10.0.0.1", 30, &why), nullptr);
    EXPECT_NE(why.find("10.0.0.1"), std::string::npos) << why;
    auto b1 = budget.try_charge("10.0.0.2", 50, &why);
    ASSERT_NE(b1, nullptr) << why;
    EXPECT_EQ(budget.held(), 90u);
    EXPECT_EQ(budget.held_by("10.0.0.1"), 40u);
    // The total is full before either address's share is.
    why.clear();
    EXPECT_EQ(budget.try_charge("10.0.0.3", 20, &why), nullptr);
    EXPECT_FALSE(why.empty());
}

TEST(TakeExportBudget, AChargeGivesItsBytesBackWhenItGoesEvenAfterTheBudget) {
    std::string why;
    auto budget = std::make_unique<TakeExportBudget>(100, 100);
    auto charge = budget->try_charge("10.0.0.1", 80, &why);
    ASSERT_NE(charge, nullptr);
    EXPECT_EQ(budget->try_charge("10.0.0.1", 30, &why), nullptr);
    charge.reset();
    EXPECT_EQ(budget->held(), 0u);
    EXPECT_EQ(budget->held_by("10.0.0.1"), 0u);
    auto again = budget->try_charge("10.0.0.1", 30, &why);
    ASSERT_NE(again, nullptr) << why;
    budget.reset();  // the daemon's budget goes first at shutdown: the charge must not touch freed books
    again.reset();
}

TEST(TakeExportBudget, ResizingToTheRealSizeIsRefusedPastTheLimitAndKeepsTheCharge) {
    TakeExportBudget budget(1000, 100);
    std::string why;
    auto charge = budget.try_charge("10.0.0.1", 20, &why);  // the estimate when asked for
    ASSERT_NE(charge, nullptr);
    EXPECT_TRUE(budget.resize(*charge, 70, &why)) << why;  // the real size once written
    EXPECT_EQ(charge->bytes(), 70u);
    EXPECT_EQ(budget.held_by("10.0.0.1"), 70u);
    EXPECT_FALSE(budget.resize(*charge, 150, &why));
    EXPECT_EQ(charge->bytes(), 70u);
    EXPECT_TRUE(budget.resize(*charge, 10, &why)) << why;  // shrinking always fits
    EXPECT_EQ(budget.held(), 10u);
}

// An export is charged as it is written: in chunks while there is room, to its exact size
// when only that fits, and refused with the reason once even that does not.
TEST(TakeExportBudget, AGrowingExportIsChargedInChunksAndRefusedOnlyPastWhatItHolds) {
    TakeExportBudget budget(1000, 100);
    std::string why;
    auto charge = budget.try_charge("10.0.0.1", 10, &why);  // one chunk when asked for
    ASSERT_NE(charge, nullptr);
    EXPECT_TRUE(budget.grow(*charge, 5, 10, &why)) << why;  // covered already
    EXPECT_EQ(charge->bytes(), 10u);
    EXPECT_TRUE(budget.grow(*charge, 11, 10, &why)) << why;  // the next chunk
    EXPECT_EQ(charge->bytes(), 20u);
    EXPECT_TRUE(budget.grow(*charge, 95, 10, &why)) << why;  // 100 fits
    EXPECT_EQ(charge->bytes(), 100u);
    EXPECT_FALSE(budget.grow(*charge, 101, 10, &why));
    EXPECT_EQ(charge->bytes(), 100u);
    EXPECT_NE(why.find("this export has grown to"), std::string::npos) << why;
    EXPECT_NE(why.find("export the take on the host"), std::string::npos) << why;  // nothing else is held
    EXPECT_TRUE(budget.resize(*charge, 50, &why)) << why;                          // its real size
    // Beside another export of the same address: the exact size when the chunk does not fit.
    auto other = budget.try_charge("10.0.0.1", 10, &why);
    ASSERT_NE(other, nullptr);
    EXPECT_TRUE(budget.grow(*other, 35, 10, &why)) << why;
    EXPECT_EQ(other->bytes(), 40u);
    EXPECT_TRUE(budget.grow(*other, 41, 30, &why)) << why;  // 50 + 60 would not fit: 41
    EXPECT_EQ(other->bytes(), 41u);
    EXPECT_FALSE(budget.grow(*other, 51, 10, &why));  // 50 + 51 > 100
    EXPECT_EQ(other->bytes(), 41u);
    EXPECT_NE(why.find("finish those downloads first"), std::string::npos) << why;
    EXPECT_EQ(budget.held_by("10.0.0.1"), 91u);
    charge.reset();
    other.reset();
    EXPECT_EQ(budget.held(), 0u);
    EXPECT_EQ(budget.held_by("10.0.0.1"), 0u);
}

// A charge of nothing grows like any other, and a refused one leaves no entry behind.
TEST(TakeExportBudget, AChargeOfNothingThatCannotGrowLeavesTheBooksEmpty) {
    TakeExportBudget budget(50, 100);
    std::string why;
    auto charge = budget.try_charge("10.0.0.9", 0, &why);
    ASSERT_NE(charge, nullptr);
    EXPECT_FALSE(budget.grow(*charge, 51, 1, &why));
    EXPECT_NE(why.find("all may hold"), std::string::npos) << why;
    EXPECT_EQ(budget.held(), 0u);
    EXPECT_EQ(budget.held_by("10.0.0.9"), 0u);
    EXPECT_TRUE(budget.grow(*charge, 50, 1, &why)) << why;
    EXPECT_EQ(budget.held(), 50u);
}

}  // namespace
}  // namespace mocap::serve
