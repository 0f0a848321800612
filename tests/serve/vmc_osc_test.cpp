// Tests of serve/vmc_osc.hpp: the bundle liblo encodes decodes (with liblo) to the VMC
// messages in order, with the rig's values.
#include "serve/vmc_osc.hpp"

#include <gtest/gtest.h>

#include "skeleton/body_model.hpp"
#include "vmc_receiver.hpp"

namespace mocap::serve {
namespace {

TEST(VmcOsc, OneBundleHoldsRootEveryBoneOkAndTime) {
    std::string error;
    const auto rig = VmcRig::build(skeleton::default_body_model(), {}, &error);
    ASSERT_TRUE(rig) << error;
    skeleton::SkeletonPose pose;
    pose.segment_count = 15;
    pose.position_m[0] = {0.25, 0.5, 0.95};
    pose.q_world_segment_wxyz[0] = {std::sqrt(0.5), 0.0, 0.0, std::sqrt(0.5)};  // turned left
    VmcPose vmc;
    rig->convert(pose, vmc);
    std::vector<char> bytes;
    ASSERT_TRUE(encode_vmc_bundle(*rig, vmc, {true, false, 12.5f}, bytes));
    ASSERT_GT(bytes.size(), 16u);
    EXPECT_EQ(std::string(bytes.data()), "#bundle");

    VmcReceiver rx;
    ASSERT_TRUE(rx.ok());
    rx.dispatch(bytes);
    ASSERT_EQ(rx.messages.size(), 3 + rig->bone_count());
    const auto& root = rx.messages.front();
    EXPECT_EQ(root.path, "/VMC/Ext/Root/Pos");
    EXPECT_EQ(root.types, "sfffffff");
    EXPECT_EQ(root.name, "root");
    EXPECT_EQ(root.floats, (std::vector<float>{-0.5f, 0.0f, 0.25f, 0.0f, 0.0f, 0.0f, 1.0f}));
    for (std::size_t i = 0; i < rig->bone_count(); ++i) {
        const auto& m = rx.messages[1 + i];
        EXPECT_EQ(m.path, "/VMC/Ext/Bone/Pos");
        EXPECT_EQ(m.types, "sfffffff");
        EXPECT_EQ(m.name, rig->bone_name(i));
        ASSERT_EQ(m.floats.size(), 7u);
        for (std::size_t k = 0; k < 3; ++k)
            EXPECT_EQ(m.floats[k], vmc.bones[i].position[k]);
        for (std::size_t k = 0; k < 4; ++k)
            EXPECT_EQ(m.floats[3 + k], vmc.bones[i].rotation_xyzw[k]);
    }
    // Hips: turned left = -90 degrees about Unity's up.
    EXPECT_NEAR(rx.messages[1].floats[4], -std::sqrt(0.5f), 1e-6f);
    const auto& ok = rx.messages[rx.messages.size() - 2];
    EXPECT_EQ(ok.path, "/VMC/Ext/OK");
    EXPECT_EQ(ok.ints, (std::vector<std::int32_t>{1, 3, 0, 0}));
    const auto& t = rx.messages.back();
    EXPECT_EQ(t.path, "/VMC/Ext/T");
    EXPECT_EQ(t.floats, (std::vector<float>{12.5f}));
}

}  // namespace
}  // namespace mocap::serve
