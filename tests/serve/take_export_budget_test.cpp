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

}  // namespace
}  // namespace mocap::serve
