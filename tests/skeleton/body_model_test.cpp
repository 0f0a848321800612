#include "skeleton/body_model.hpp"

#include <gtest/gtest.h>

#include <algorithm>

namespace mocap::skeleton {
namespace {

bool any_contains(const std::vector<std::string>& errors, const std::string& what) {
    return std::any_of(errors.begin(), errors.end(), [&](const std::string& e) { return e.find(what) != e.npos; });
}

const SegmentDef& by_name(const BodyModel& m, std::string_view n) {
    const int i = m.index_of(n);
    EXPECT_GE(i, 0) << n;
    return m.segments[static_cast<std::size_t>(i)];
}

TEST(BodyModel, DefaultIsValidWithTheSeedHierarchy) {
    const BodyModel m = default_body_model();
    EXPECT_TRUE(validate(m).empty());
    ASSERT_EQ(m.size(), 15u);
    EXPECT_EQ(m.segments[0].name, "pelvis");
    EXPECT_EQ(m.segments[0].parent, -1);
    const auto parent_name = [&](std::string_view n) {
        return m.segments[static_cast<std::size_t>(by_name(m, n).parent)].name;
    };
    EXPECT_EQ(parent_name("trunk"), "pelvis");
    EXPECT_EQ(parent_name("head"), "trunk");
    for (const std::string side : {"left", "right"}) {
        EXPECT_EQ(parent_name(side + "_upper_arm"), "trunk");
        EXPECT_EQ(parent_name(side + "_forearm"), side + "_upper_arm");
        EXPECT_EQ(parent_name(side + "_hand"), side + "_forearm");
        EXPECT_EQ(parent_name(side + "_thigh"), "pelvis");
        EXPECT_EQ(parent_name(side + "_calf"), side + "_thigh");
        EXPECT_EQ(parent_name(side + "_foot"), side + "_calf");
    }
    for (std::size_t i = 0; i < m.size(); ++i)
        EXPECT_EQ(m.segments[i].node_id, static_cast<int>(i) + 1);
}

TEST(BodyModel, DefaultDimensionsFollowWinterRatios) {
    const double h = 1.80;
    const BodyModel m = default_body_model(h);
    EXPECT_NEAR(m.root_height_m, 0.530 * h, 1e-12);
    // Leg: thigh + shank + ankle height reaches the floor from the hip.
    const double leg = -by_name(m, "left_calf").offset_m.z() - by_name(m, "left_foot").offset_m.z() -
                       by_name(m, "left_foot").end_m.z();
    EXPECT_NEAR(leg, m.root_height_m, 1e-12);
    // Left is +y, right is -y, mirror images.
    EXPECT_GT(by_name(m, "left_upper_arm").offset_m.y(), 0.0);
    EXPECT_NEAR(by_name(m, "left_upper_arm").offset_m.y(), -by_name(m, "right_upper_arm").offset_m.y(), 1e-12);
    EXPECT_NEAR(by_name(m, "left_forearm").offset_m.norm(), 0.186 * h, 1e-12);
    // Top of the head at the full height.
    const double top = m.root_height_m + by_name(m, "trunk").offset_m.z() + by_name(m, "head").offset_m.z() +
                       by_name(m, "head").end_m.z();
    EXPECT_NEAR(top, h, 1e-12);
}

TEST(BodyModel, RejectsBrokenModelsWithMessages) {
    {
        BodyModel m;
        EXPECT_TRUE(any_contains(validate(m), "no segments"));
    }
    {
        BodyModel m = default_body_model();
        m.segments[3].name = m.segments[1].name;
        EXPECT_TRUE(any_contains(validate(m), "duplicate segment name"));
    }
    {
        BodyModel m = default_body_model();
        m.segments[3].name = "left arm";
        EXPECT_TRUE(any_contains(validate(m), "[A-Za-z0-9_]"));
    }
    {
        BodyModel m = default_body_model();
        m.segments[5].parent = -1;
        const auto e = validate(m);
        EXPECT_TRUE(any_contains(e, "only segment 0 may be the root"));
        EXPECT_TRUE(any_contains(e, "exactly one root"));
    }
    {
        BodyModel m = default_body_model();
        m.segments[1].parent = 4;  // child before parent (a cycle is impossible to express then)
        EXPECT_TRUE(any_contains(validate(m), "must come before its child"));
    }
    {
        BodyModel m = default_body_model();
        m.segments[2].parent = 99;
        EXPECT_TRUE(any_contains(validate(m), "out of range"));
    }
    {
        BodyModel m = default_body_model();
        m.segments[7].node_id = m.segments[2].node_id;
        EXPECT_TRUE(any_contains(validate(m), "used by another segment"));
        m.segments[7].node_id = 200;
        EXPECT_TRUE(any_contains(validate(m), "outside 0..127"));
        m.segments[7].node_id = -1;
        m.segments[8].node_id = -1;  // several segments without a sensor are fine
        EXPECT_TRUE(validate(m).empty());
    }
    {
        BodyModel m = default_body_model();
        m.segments[4].offset_m.x() = std::nan("");
        EXPECT_TRUE(any_contains(validate(m), "offset must be finite"));
    }
    {
        BodyModel m = default_body_model();
        while (m.size() <= kMaxSegments) {
            SegmentDef s;
            s.name = "extra" + std::to_string(m.size());
            s.parent = 0;
            m.segments.push_back(s);
        }
        EXPECT_TRUE(any_contains(validate(m), "at most"));
    }
}

}  // namespace
}  // namespace mocap::skeleton
