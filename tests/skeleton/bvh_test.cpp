#include "skeleton/bvh.hpp"
#include "skeleton/bvh_mapping.hpp"
#include "skeleton/bvh_write.hpp"

#include <gtest/gtest.h>

#include <fstream>
#include <random>
#include <sstream>

#include "skeleton/body_model.hpp"
#include "skeleton/forward_kinematics.hpp"

namespace mocap::skeleton {
namespace {

std::string read_text(const std::string& name) {
    std::ifstream f(std::string(MOCAP_SKELETON_TEST_DATA) + "/" + name);
    std::stringstream ss;
    ss << f.rdbuf();
    return ss.str();
}

// Independent counts: whitespace tokens ROOT/JOINT, the CHANNELS numbers, and the
// non-blank lines after "Frame Time:".
struct Counts {
    std::size_t joints = 0;
    std::size_t channels = 0;
    std::size_t rows = 0;
    std::size_t declared_frames = 0;
};
Counts count_independently(const std::string& text) {
    Counts c;
    std::istringstream in(text);
    std::string line;
    bool motion = false;
    while (std::getline(in, line)) {
        std::istringstream ls(line);
        std::string first;
        ls >> first;
        if (motion) {
            if (!first.empty()) ++c.rows;
            continue;
        }
        if (first == "ROOT" || first == "JOINT") ++c.joints;
        if (first == "CHANNELS") {
            std::size_t n = 0;
            ls >> n;
            c.channels += n;
        }
        if (first == "Frames:") ls >> c.declared_frames;
        if (first == "Frame") motion = true;
    }
    return c;
}

double deg(double rad) {
    return rad * 180.0 / M_PI;
}

Quat random_quat(std::mt19937& rng) {
    std::normal_distribution<double> n;
    return Quat(n(rng), n(rng), n(rng), n(rng)).normalized();
}

TEST(Bvh, CmuClipsParseWithTheCountsInTheFile) {
    for (const auto& [name, frames] : {std::pair<std::string, std::size_t>{"cmu_131_01_walk.bvh", 995},
                                       std::pair<std::string, std::size_t>{"cmu_131_03_hop.bvh", 1248}}) {
        const std::string text = read_text(name);
        ASSERT_FALSE(text.empty()) << name;
        const Counts c = count_independently(text);
        EXPECT_EQ(c.joints, 31u);
        EXPECT_EQ(c.rows, frames);
        const auto r = parse_bvh(text);
        ASSERT_TRUE(r) << name << ": " << r.error;
        const BvhClip& clip = *r.clip;
        EXPECT_EQ(clip.joints.size(), c.joints);
        EXPECT_EQ(clip.channels_per_frame, c.channels);
        EXPECT_EQ(clip.channels_per_frame, 6u + 3u * 30u);
        EXPECT_EQ(clip.frame_count, c.rows);
        EXPECT_EQ(clip.frame_count, c.declared_frames);
        EXPECT_NEAR(clip.frame_time_s, 0.008333, 1e-9);
        EXPECT_EQ(clip.values.size(), clip.frame_count * clip.channels_per_frame);
        EXPECT_EQ(clip.joints[0].name, "Hips");
        EXPECT_EQ(clip.joints[0].channel_count, 6);
        const int elbow = clip.index_of("LeftElbow");
        ASSERT_GE(elbow, 0);
        EXPECT_EQ(clip.joints[static_cast<std::size_t>(elbow)].channels[1], BvhChannel::kXrotation);
        EXPECT_EQ(clip.joints[static_cast<std::size_t>(clip.index_of("LeftElbow"))].parent,
                  clip.index_of("LeftShoulder"));
    }
}

TEST(Bvh, WriteThenReadReproducesTheClip) {
    const auto a = parse_bvh(read_text("cmu_131_01_walk.bvh"));
    ASSERT_TRUE(a) << a.error;
    const auto b = parse_bvh(write_bvh(*a.clip));
    ASSERT_TRUE(b) << b.error;
    const BvhClip &ca = *a.clip, &cb = *b.clip;
    ASSERT_EQ(ca.joints.size(), cb.joints.size());
    for (std::size_t j = 0; j < ca.joints.size(); ++j) {
        EXPECT_EQ(ca.joints[j].name, cb.joints[j].name);
        EXPECT_EQ(ca.joints[j].parent, cb.joints[j].parent);
        EXPECT_EQ(ca.joints[j].channel_count, cb.joints[j].channel_count);
        EXPECT_EQ(ca.joints[j].channels, cb.joints[j].channels);
        EXPECT_EQ(ca.joints[j].has_end_site, cb.joints[j].has_end_site);
        EXPECT_LT((ca.joints[j].offset - cb.joints[j].offset).norm(), 1e-6);
        EXPECT_LT((ca.joints[j].end_offset - cb.joints[j].end_offset).norm(), 1e-6);
    }
    ASSERT_EQ(ca.values.size(), cb.values.size());
    double worst = 0;
    for (std::size_t i = 0; i < ca.values.size(); ++i)
        worst = std::max(worst, std::abs(ca.values[i] - cb.values[i]));
    EXPECT_LT(worst, 5e-7);
    EXPECT_EQ(ca.frame_time_s, cb.frame_time_s);
}

TEST(Bvh, YUpMapsToEnuZUp) {
    // Root turned 90° about BVH Y (up): in ENU that is 90° about z. The child offset along
    // BVH +X (the left) ends up along ENU +y before the turn, -x after it.
    const std::string text =
        "HIERARCHY\nROOT r\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition Yrotation Xrotation Zrotation\n"
        " JOINT c\n {\n  OFFSET 1 0 0\n  CHANNELS 3 Zrotation Xrotation Yrotation\n  End Site\n  {\n   OFFSET 0 1 0\n  "
        "}\n"
        " }\n}\nMOTION\nFrames: 2\nFrame Time: 0.01\n1 2 3 0 0 0 0 0 0\n1 2 3 90 0 0 0 0 0\n";
    const auto r = parse_bvh(text);
    ASSERT_TRUE(r) << r.error;
    std::array<Quat, 2> q;
    std::array<Vec3, 2> p;
    bvh_global_pose(*r.clip, r.clip->frame(0), 1.0, q, p);
    EXPECT_LT(q[0].angularDistance(Quat::Identity()), 1e-12);
    EXPECT_LT((p[0] - Vec3(3, 1, 2)).norm(), 1e-12);  // x_enu = Z, y_enu = X, z_enu = Y
    EXPECT_LT((p[1] - Vec3(3, 2, 2)).norm(), 1e-12);
    bvh_global_pose(*r.clip, r.clip->frame(1), 1.0, q, p);
    EXPECT_LT(q[0].angularDistance(Quat(Eigen::AngleAxisd(M_PI / 2, Vec3::UnitZ()))), 1e-12);
    EXPECT_LT((p[1] - Vec3(2, 1, 2)).norm(), 1e-12);
    EXPECT_LT((q_enu_bvh()._transformVector(Vec3(1, 2, 3)) - enu_from_bvh(Vec3(1, 2, 3))).norm(), 1e-12);
    EXPECT_LT((bvh_from_enu(enu_from_bvh(Vec3(1, 2, 3))) - Vec3(1, 2, 3)).norm(), 1e-12);
}

TEST(Bvh, CmuRestPoseIsUprightFacingEnuX) {
    const auto r = parse_bvh(read_text("cmu_131_01_walk.bvh"));
    ASSERT_TRUE(r);
    const BvhClip& clip = *r.clip;
    std::vector<double> zeros(clip.channels_per_frame, 0.0);
    std::vector<Quat> q(clip.joints.size());
    std::vector<Vec3> p(clip.joints.size());
    bvh_global_pose(clip, zeros, 1.0, q, p);
    auto pos = [&](const char* n) { return p[static_cast<std::size_t>(clip.index_of(n))]; };
    EXPECT_GT(pos("Head").z(), pos("Hips").z() + 0.4);
    EXPECT_LT(pos("LeftAnkle").z(), pos("Hips").z() - 0.7);
    EXPECT_GT(pos("LeftHip").y(), 0.05);  // left is +y
    EXPECT_LT(pos("RightHip").y(), -0.05);
    EXPECT_GT(pos("LeftToe").x(), pos("LeftAnkle").x());  // toes point forward, +x
}

// The model writer: random segment orientations -> MOTION line -> parse -> global pose
// gives the same orientations, and the joint positions follow the model's offsets.
TEST(Bvh, ModelWriterRoundTripsOrientationsInEveryOrder) {
    const BodyModel model = default_body_model();
    std::mt19937 rng(3);
    for (const char* order : {"ZXY", "XYZ", "YZX", "ZYX"}) {
        BvhWriteOptions opt;
        opt.order = *parse_rotation_order(order);
        opt.decimals = 6;
        std::string text = bvh_hierarchy_text(model, opt);
        const int frames = 20;
        text += bvh_motion_header(frames, 0.01);
        std::vector<std::array<Quat, kMaxSegments>> truth(frames);
        std::vector<Vec3> roots;
        for (int f = 0; f < frames; ++f) {
            for (std::size_t i = 0; i < model.size(); ++i)
                truth[static_cast<std::size_t>(f)][i] = random_quat(rng);
            roots.emplace_back(0.1 * f, -0.2, 0.9);
            append_bvh_motion_line(model, opt, truth[static_cast<std::size_t>(f)], roots.back(), text);
        }
        const auto r = parse_bvh(text);
        ASSERT_TRUE(r) << r.error;
        const BvhClip& clip = *r.clip;
        ASSERT_EQ(clip.joints.size(), model.size());
        EXPECT_EQ(clip.channels_per_frame, bvh_values_per_frame(model));
        for (std::size_t i = 0; i < model.size(); ++i)
            EXPECT_EQ(clip.joints[i].name, model.segments[i].name);
        std::vector<Quat> q(model.size());
        std::vector<Vec3> p(model.size());
        for (int f = 0; f < frames; ++f) {
            bvh_global_pose(clip, clip.frame(static_cast<std::size_t>(f)), 0.01, q, p);
            for (std::size_t i = 0; i < model.size(); ++i) {
                EXPECT_LT(deg(q[i].angularDistance(truth[static_cast<std::size_t>(f)][i])), 1e-3) << order << " " << i;
                if (model.segments[i].parent >= 0) {
                    const auto par = static_cast<std::size_t>(model.segments[i].parent);
                    const Vec3 expect =
                        p[par] + truth[static_cast<std::size_t>(f)][par]._transformVector(model.segments[i].offset_m);
                    EXPECT_LT((p[i] - expect).norm(), 1e-6);
                }
            }
            EXPECT_LT((p[0] - roots[static_cast<std::size_t>(f)]).norm(), 1e-6);
        }
    }
}

TEST(Bvh, ModelHierarchyHasEndSitesAtLeavesOnly) {
    const BodyModel model = default_body_model();
    const auto r = parse_bvh_hierarchy(bvh_hierarchy_text(model));
    ASSERT_TRUE(r) << r.error;
    int ends = 0;
    for (const BvhJoint& j : r.clip->joints)
        ends += j.has_end_site ? 1 : 0;
    EXPECT_EQ(ends, 5);  // head, two hands, two feet
    // Offsets in centimetres, BVH axes: the left thigh hangs off the pelvis at +X.
    const BvhJoint& thigh = r.clip->joints[static_cast<std::size_t>(r.clip->index_of("left_thigh"))];
    EXPECT_NEAR(thigh.offset.x(),
                100.0 * model.segments[static_cast<std::size_t>(model.index_of("left_thigh"))].offset_m.y(), 1e-6);
    EXPECT_NEAR(r.clip->joints[0].offset.y(), 100.0 * model.root_height_m, 1e-6);
}

// Mapping CMU joints onto the 15 segments: each segment's long axis follows the clip's bone.
/// Each (segment, BVH joint) pair: the segment is driven by that joint.
void expect_mapped(const BvhClip& clip, const BodyModel& model, const BvhSegmentMapping& m,
                   const std::vector<std::pair<std::string, std::string>>& expected) {
    for (const auto& [seg, joint] : expected) {
        const int i = model.index_of(seg);
        ASSERT_GE(i, 0) << seg;
        EXPECT_EQ(clip.joints[static_cast<std::size_t>(m.joint[static_cast<std::size_t>(i)])].name, joint) << seg;
    }
}

struct MappedClip {
    BvhClip clip;
    BodyModel model = default_body_model();
    BvhMappingResult m;
};
MappedClip load_mapped(const std::string& name) {
    MappedClip c;
    auto r = parse_bvh(read_text(name));
    EXPECT_TRUE(r) << r.error;
    if (r) c.clip = std::move(*r.clip);
    const auto sources = cmu_segment_sources();
    c.m = map_bvh_to_model(c.clip, c.model, sources);
    EXPECT_TRUE(c.m) << c.m.error;
    return c;
}

TEST(Bvh, CmuMappingFollowsTheBones) {
    const MappedClip mc = load_mapped("cmu_131_03_hop.bvh");
    ASSERT_TRUE(mc.m);
    const BvhClip& clip = mc.clip;
    const BodyModel& model = mc.model;
    const auto& m = mc.m;
    expect_mapped(clip, model, *m.mapping,
                  {{"pelvis", "Hips"},
                   {"trunk", "Chest2"},
                   {"head", "Head"},
                   {"left_upper_arm", "LeftShoulder"},
                   {"right_forearm", "RightElbow"},
                   {"left_hand", "lhand"},
                   {"right_thigh", "RightHip"},
                   {"left_calf", "LeftKnee"},
                   {"right_foot", "RightAnkle"}});

    const std::vector<std::pair<std::string, std::string>> bones{{"left_upper_arm", "LeftElbow"},
                                                                 {"right_forearm", "RightWrist"},
                                                                 {"left_thigh", "LeftKnee"},
                                                                 {"right_calf", "RightAnkle"},
                                                                 {"left_foot", "LeftToe"}};
    std::vector<Quat> qj(clip.joints.size());
    std::vector<Vec3> pj(clip.joints.size());
    std::array<Quat, kMaxSegments> qs;
    std::array<Vec3, kMaxSegments> ps;
    double worst_deg = 0;
    for (std::size_t f = 0; f < clip.frame_count; f += 7) {
        bvh_global_pose(clip, clip.frame(f), 1.0, qj, pj);
        bvh_segment_pose(*m.mapping, qj, pj, qs, ps);
        for (const auto& [seg, tip] : bones) {
            const auto i = static_cast<std::size_t>(model.index_of(seg));
            const Vec3 axis = qs[i]._transformVector(model.segments[i].end_m).normalized();
            const Vec3 bone = (pj[static_cast<std::size_t>(clip.index_of(tip))] - ps[i]).normalized();
            worst_deg = std::max(worst_deg, deg(std::acos(std::clamp(axis.dot(bone), -1.0, 1.0))));
        }
    }
    EXPECT_LT(worst_deg, 1e-4);  // acos near 1 limits the resolution
    // Standing at the start: calves point down, the head up.
    bvh_global_pose(clip, clip.frame(0), 1.0, qj, pj);
    bvh_segment_pose(*m.mapping, qj, pj, qs, ps);
    const auto calf = static_cast<std::size_t>(model.index_of("left_calf"));
    EXPECT_LT(qs[calf]._transformVector(-Vec3::UnitZ()).z(), -0.9);
}

TEST(Bvh, CmuRoundTripThroughTheModelWriter) {
    // read CMU -> segment orientations -> write with the 15-segment model -> read -> same.
    const MappedClip mc = load_mapped("cmu_131_01_walk.bvh");
    ASSERT_TRUE(mc.m);
    const BvhClip& clip = mc.clip;
    const BodyModel& model = mc.model;
    const auto& m = mc.m;
    std::vector<Quat> qj(clip.joints.size());
    std::vector<Vec3> pj(clip.joints.size());
    std::vector<std::array<Quat, kMaxSegments>> truth(clip.frame_count);
    std::array<Vec3, kMaxSegments> ps;
    BvhWriteOptions opt;
    std::string text = bvh_hierarchy_text(model, opt) + bvh_motion_header(clip.frame_count, clip.frame_time_s);
    for (std::size_t f = 0; f < clip.frame_count; ++f) {
        bvh_global_pose(clip, clip.frame(f), 1.0, qj, pj);
        bvh_segment_pose(*m.mapping, qj, pj, truth[f], ps);
        append_bvh_motion_line(model, opt, truth[f], ps[0], text);
    }
    const auto back = parse_bvh(text);
    ASSERT_TRUE(back) << back.error;
    ASSERT_EQ(back.clip->frame_count, clip.frame_count);
    std::vector<Quat> q2(model.size());
    std::vector<Vec3> p2(model.size());
    double worst = 0;
    for (std::size_t f = 0; f < clip.frame_count; ++f) {
        bvh_global_pose(*back.clip, back.clip->frame(f), 0.01, q2, p2);
        for (std::size_t i = 0; i < model.size(); ++i)
            worst = std::max(worst, deg(q2[i].angularDistance(truth[f][i])));
    }
    EXPECT_LT(worst, 0.01);  // 4 decimals of a degree per angle
}

TEST(Bvh, MappingErrorsNameTheSegment) {
    const auto r = parse_bvh_hierarchy(bvh_hierarchy_text(default_body_model()));
    ASSERT_TRUE(r);
    const auto m = map_bvh_to_model(*r.clip, default_body_model(), cmu_segment_sources());
    EXPECT_FALSE(m);
    EXPECT_NE(m.error.find("pelvis"), std::string::npos);
}

// --- malformed input -------------------------------------------------------------------

const std::string kHead =
    "HIERARCHY\nROOT r\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
    " JOINT c\n {\n  OFFSET 1 0 0\n  CHANNELS 3 Zrotation Xrotation Yrotation\n  End Site\n  {\n   OFFSET 0 1 0\n  }\n"
    " }\n}\n";

// A value beyond fixed-point range once came out of write_bvh as the garbage left in a too
// small buffer (found by fuzz_bvh); it must be written so that it reads back exactly.
TEST(Bvh, ValuesBeyondFixedPointRangeRoundTrip) {
    auto a = parse_bvh(read_text("cmu_131_01_walk.bvh"));
    ASSERT_TRUE(a) << a.error;
    BvhClip clip = *a.clip;
    clip.values[3] = -2e73;
    clip.values[4] = 1.7976931348623157e308;
    clip.values[5] = 12345678901.25;
    const std::string text = write_bvh(clip);
    const auto b = parse_bvh(text);
    ASSERT_TRUE(b) << b.error;
    EXPECT_EQ(b.clip->values[3], -2e73);
    EXPECT_EQ(b.clip->values[4], 1.7976931348623157e308);
    EXPECT_EQ(b.clip->values[5], 12345678901.25);
}

std::string error_of(const std::string& text, const BvhLimits& limits = {}) {
    const auto r = parse_bvh(text, limits);
    EXPECT_FALSE(r) << text;
    return r.error;
}

TEST(BvhMalformed, GoodBaseParses) {
    EXPECT_TRUE(parse_bvh(kHead + "MOTION\nFrames: 1\nFrame Time: 0.01\n1 2 3 4 5 6 7 8 9\n"));
    // Trailing blank lines and CRLF are fine.
    EXPECT_TRUE(parse_bvh(kHead + "MOTION\r\nFrames: 1\r\nFrame Time: 0.01\r\n1 2 3 4 5 6 7 8 9\r\n\r\n"));
}

TEST(BvhMalformed, ValueCounts) {
    EXPECT_NE(error_of(kHead + "MOTION\nFrames: 1\nFrame Time: 0.01\n1 2 3 4 5 6 7 8 9 10\n").find("too many values"),
              std::string::npos);
    EXPECT_NE(
        error_of(kHead + "MOTION\nFrames: 1\nFrame Time: 0.01\n1 2 3 4 5 6 7 8\n").find("expected 9 values, found 8"),
        std::string::npos);
    EXPECT_NE(error_of(kHead + "MOTION\nFrames: 2\nFrame Time: 0.01\n1 2 3 4 5 6 7 8 9\n").find("but 1 motion rows"),
              std::string::npos);
    EXPECT_NE(error_of(kHead + "MOTION\nFrames: 1\nFrame Time: 0.01\n1 2 3 4 5 6 7 8 9\n1 2 3 4 5 6 7 8 9\n")
                  .find("more motion rows"),
              std::string::npos);
}

TEST(BvhMalformed, NumbersAndChannels) {
    const std::string e = error_of(kHead + "MOTION\nFrames: 1\nFrame Time: 0.01\n1 2 3 4 x5 6 7 8 9\n");
    EXPECT_NE(e.find("line 19"), std::string::npos) << e;
    EXPECT_NE(e.find("not a finite number"), std::string::npos);
    EXPECT_NE(error_of(kHead + "MOTION\nFrames: 1\nFrame Time: 0.01\n1 2 3 4 nan 6 7 8 9\n").find("finite"),
              std::string::npos);
    EXPECT_NE(error_of(kHead + "MOTION\nFrames: 1\nFrame Time: 0.01\n1 2 3 4 1e999 6 7 8 9\n").find("finite"),
              std::string::npos);
    EXPECT_NE(error_of(kHead + "MOTION\nFrames: x\nFrame Time: 0.01\n").find("Frames"), std::string::npos);
    EXPECT_NE(error_of(kHead + "MOTION\nFrames: 1\nFrame Time: -1\n1 2 3 4 5 6 7 8 9\n").find("Frame Time"),
              std::string::npos);
    std::string bad = kHead;
    bad.replace(bad.find("Xrotation Yrotation\n  End"), 9, "Wrotation");
    EXPECT_NE(error_of(bad).find("unknown channel 'Wrotation'"), std::string::npos);
    bad = kHead;
    bad.replace(bad.find("CHANNELS 3"), 10, "CHANNELS 7");
    EXPECT_NE(error_of(bad).find("0..6"), std::string::npos);
    bad = kHead;
    bad.replace(bad.find("Zrotation Xrotation Yrotation\n  End"), 29, "Zrotation Zrotation Yrotation");
    EXPECT_NE(error_of(bad).find("listed twice"), std::string::npos);
    bad = kHead;
    bad.replace(bad.find("OFFSET 1 0 0"), 12, "OFFSET 1 0");
    EXPECT_NE(error_of(bad).find("OFFSET needs 3 finite numbers"), std::string::npos);
}

TEST(BvhMalformed, Structure) {
    EXPECT_NE(error_of("").find("expected 'HIERARCHY'"), std::string::npos);
    EXPECT_NE(error_of("HIERARCHY\nJOINT a\n").find("expected 'ROOT'"), std::string::npos);
    EXPECT_NE(error_of(kHead.substr(0, kHead.find("End Site"))).find("unexpected end of file inside joint 'c'"),
              std::string::npos);
    EXPECT_NE(error_of(kHead).find("expected 'MOTION', found end of file"), std::string::npos);
    EXPECT_NE(error_of(kHead + kHead.substr(10)).find("only one ROOT"), std::string::npos);
    EXPECT_NE(
        error_of("HIERARCHY\nROOT r\n{\n OFFSET 0 0 0\n CHANNELS 0\n JOINT r\n {\n OFFSET 0 0 0\n CHANNELS 0\n }\n}\n")
            .find("duplicate joint name"),
        std::string::npos);
    EXPECT_NE(
        error_of("HIERARCHY\nROOT r\n{\n OFFSET 0 0 0\n CHANNELS 0\n End Site\n {\n OFFSET 0 0 0\n CHANNELS 0\n }\n}\n")
            .find("CHANNELS inside an End Site"),
        std::string::npos);
    EXPECT_NE(error_of("HIERARCHY\nROOT r\n{\n CHANNELS 0\n}\n").find("has no OFFSET"), std::string::npos);
    EXPECT_NE(error_of("HIERARCHY\nROOT r\n{\n OFFSET 0 0 0\n JOINT a\n").find("needs OFFSET and CHANNELS"),
              std::string::npos);
    EXPECT_NE(error_of("HIERARCHY\nROOT r\n{\n OFFSET 0 0 0\n CHANNELS 0\n MOTION\n").find("unexpected 'MOTION'"),
              std::string::npos);
}

TEST(BvhMalformed, BoundsHoldAgainstHostileSizes) {
    BvhLimits lim;
    lim.max_depth = 8;
    lim.max_joints = 10;
    // Nesting deeper than the limit.
    std::string deep = "HIERARCHY\nROOT j0\n{\nOFFSET 0 0 0\nCHANNELS 0\n";
    for (int i = 1; i < 20; ++i)
        deep += "JOINT j" + std::to_string(i) + "\n{\nOFFSET 0 0 0\nCHANNELS 0\n";
    EXPECT_NE(error_of(deep, lim).find("deeper than 8"), std::string::npos);
    // More joints than the limit (flat).
    std::string wide = "HIERARCHY\nROOT j0\n{\nOFFSET 0 0 0\nCHANNELS 0\n";
    for (int i = 1; i < 20; ++i)
        wide += "JOINT j" + std::to_string(i) + "\n{\nOFFSET 0 0 0\nCHANNELS 0\n}\n";
    EXPECT_NE(error_of(wide, lim).find("more than 10 joints"), std::string::npos);
    // A huge declared frame count with no rows is an error, not an allocation.
    EXPECT_NE(error_of(kHead + "MOTION\nFrames: 999999999999\nFrame Time: 0.01\n").find("frames"), std::string::npos);
    BvhLimits small;
    small.max_values = 100;
    EXPECT_NE(error_of(kHead + "MOTION\nFrames: 12\nFrame Time: 0.01\n", small).find("exceeds 100 values"),
              std::string::npos);
    EXPECT_NE(error_of(kHead + "MOTION\nFrames: 99999999999999999999999\nFrame Time: 0.01\n").find("Frames"),
              std::string::npos);
    EXPECT_NE(error_of("HIERARCHY\nROOT " + std::string(5000, 'a') + "\n").find("token too long"), std::string::npos);
}

TEST(BvhMotionLine, ParsesExactCounts) {
    std::array<double, 3> v{};
    EXPECT_EQ(parse_bvh_motion_line(" 1 -2.5\t3e2 \r", v), "");
    EXPECT_EQ(v[2], 300.0);
    EXPECT_NE(parse_bvh_motion_line("1 2", v), "");
    EXPECT_NE(parse_bvh_motion_line("1 2 3 4", v), "");
}

}  // namespace
}  // namespace mocap::skeleton

namespace mocap::skeleton {
namespace {

// Random edits of a valid file: the parser must return (clip or error) without crashing,
// and every clip it accepts must be internally consistent and evaluate to finite poses.
TEST(BvhMalformed, RandomMutationsAreRejectedOrConsistent) {
    const std::string base = kHead +
                             "MOTION\nFrames: 3\nFrame Time: 0.01\n1 2 3 4 5 6 7 8 9\n"
                             "-1 -2 -3 -4 -5 -6 -7 -8 -9\n0.5 0.5 0.5 90 90 90 0 0 0\n";
    const std::string alphabet = "0123456789-.e+ \t\n{}XYZrotainpsJOINTEnd SiteFrames:Time";
    std::mt19937 rng(11);
    std::size_t accepted = 0;
    for (int k = 0; k < 20000; ++k) {
        std::string t = base;
        const int edits = 1 + static_cast<int>(rng() % 3);
        for (int e = 0; e < edits && !t.empty(); ++e) {
            const std::size_t at = rng() % t.size();
            switch (rng() % 4) {
                case 0:
                    t[at] = alphabet[rng() % alphabet.size()];
                    break;
                case 1:
                    t.erase(at, 1 + rng() % 8);
                    break;
                case 2:
                    t.insert(at, t.substr(rng() % t.size(), 1 + rng() % 16));
                    break;
                default:
                    t.resize(at);
                    break;
            }
        }
        const auto r = parse_bvh(t);
        if (!r) {
            EXPECT_FALSE(r.error.empty());
            continue;
        }
        ++accepted;
        const BvhClip& c = *r.clip;
        std::size_t channels = 0;
        for (std::size_t j = 0; j < c.joints.size(); ++j) {
            ASSERT_LT(c.joints[j].parent, static_cast<int>(j));
            ASSERT_EQ(c.joints[j].first_channel, channels);
            channels += c.joints[j].channel_count;
        }
        ASSERT_EQ(c.channels_per_frame, channels);
        ASSERT_EQ(c.values.size(), c.frame_count * c.channels_per_frame);
        std::vector<Quat> q(c.joints.size());
        std::vector<Vec3> p(c.joints.size());
        for (std::size_t f = 0; f < c.frame_count; ++f) {
            bvh_global_pose(c, c.frame(f), 1.0, q, p);
            for (std::size_t j = 0; j < c.joints.size(); ++j) {
                ASSERT_TRUE(q[j].coeffs().allFinite() && p[j].allFinite());
            }
        }
    }
    EXPECT_GT(accepted, 0u);  // some edits (digits in numbers) leave a valid file
}

}  // namespace
}  // namespace mocap::skeleton

namespace mocap::skeleton {
namespace {

// The other common CMU conversion names the collar "LeftShoulder" and the upper arm
// "LeftArm"; the mapping must pick the upper arm, not the collar.
TEST(Bvh, SecondCmuNamingMapsToTheRightJoints) {
    struct J {
        const char* name;
        const char* parent;
        double x, y, z;
    };
    const std::vector<J> joints{
        {"Hips", "", 0, 0, 0},
        {"LowerBack", "Hips", 0, 0.1, 0},
        {"Spine", "LowerBack", 0, 0.1, 0},
        {"Spine1", "Spine", 0, 0.1, 0},
        {"Neck", "Spine1", 0, 0.1, 0},
        {"Head", "Neck", 0, 0.1, 0},
        {"LeftShoulder", "Spine1", 0.05, 0.05, 0},
        {"LeftArm", "LeftShoulder", 0.15, 0, 0},
        {"LeftForeArm", "LeftArm", 0, -0.3, 0},
        {"LeftHand", "LeftForeArm", 0, -0.25, 0},
        {"RightShoulder", "Spine1", -0.05, 0.05, 0},
        {"RightArm", "RightShoulder", -0.15, 0, 0},
        {"RightForeArm", "RightArm", 0, -0.3, 0},
        {"RightHand", "RightForeArm", 0, -0.25, 0},
        {"LHipJoint", "Hips", 0.1, 0, 0},
        {"LeftUpLeg", "LHipJoint", 0, -0.05, 0},
        {"LeftLeg", "LeftUpLeg", 0, -0.4, 0},
        {"LeftFoot", "LeftLeg", 0, -0.4, 0},
        {"LeftToeBase", "LeftFoot", 0, -0.05, 0.12},
        {"RHipJoint", "Hips", -0.1, 0, 0},
        {"RightUpLeg", "RHipJoint", 0, -0.05, 0},
        {"RightLeg", "RightUpLeg", 0, -0.4, 0},
        {"RightFoot", "RightLeg", 0, -0.4, 0},
        {"RightToeBase", "RightFoot", 0, -0.05, 0.12},
    };
    BvhClip clip;
    for (const J& j : joints) {
        BvhJoint b;
        b.name = j.name;
        b.parent = clip.index_of(j.parent);
        b.offset = Vec3(j.x, j.y, j.z);
        b.has_end_site = std::string(j.name) == "Head" || std::string(j.name).find("Hand") != std::string::npos ||
                         std::string(j.name).find("Toe") != std::string::npos;
        b.end_offset = std::string(j.name) == "Head" ? Vec3(0, 0.2, 0) : Vec3(0, -0.1, 0);
        clip.joints.push_back(b);
    }
    const BodyModel model = default_body_model();
    const auto sources = cmu_segment_sources();
    const auto m = map_bvh_to_model(clip, model, sources);
    ASSERT_TRUE(m) << m.error;
    expect_mapped(clip, model, *m.mapping,
                  {{"trunk", "Spine1"},
                   {"left_upper_arm", "LeftArm"},
                   {"right_forearm", "RightForeArm"},
                   {"left_hand", "LeftHand"},
                   {"right_thigh", "RightUpLeg"},
                   {"left_calf", "LeftLeg"},
                   {"right_foot", "RightFoot"}});
}

}  // namespace
}  // namespace mocap::skeleton

namespace mocap::skeleton {
namespace {

// A model with the clip's own dimensions: forward kinematics with the mapped segment
// orientations lands on the clip's leg joints; the arms hang from the clip's collar
// joints, which rotate (up to 16 cm shoulder travel in this clip) while the model's
// shoulders are rigid with the trunk, so for the arms the bone vectors are compared.
TEST(Bvh, ModelFromClipReproducesLimbPositions) {
    const MappedClip mc = load_mapped("cmu_131_01_walk.bvh");
    ASSERT_TRUE(mc.m);
    const BodyModel model = body_model_from_bvh(mc.clip, *mc.m.mapping, mc.model, 1.0);
    EXPECT_TRUE(validate(model).empty());
    EXPECT_NEAR(model.segments[static_cast<std::size_t>(model.index_of("left_calf"))].offset_m.norm(), 0.411471, 1e-5);
    const std::vector<std::pair<std::string, std::string>> legs{
        {"left_thigh", "LeftHip"},   {"left_calf", "LeftKnee"},   {"left_foot", "LeftAnkle"},
        {"right_thigh", "RightHip"}, {"right_calf", "RightKnee"}, {"right_foot", "RightAnkle"}};
    const std::vector<std::pair<std::string, std::string>> arm_bones{
        {"left_upper_arm", "LeftShoulder"},   {"left_forearm", "LeftElbow"},   {"left_hand", "LeftWrist"},
        {"right_upper_arm", "RightShoulder"}, {"right_forearm", "RightElbow"}, {"right_hand", "RightWrist"}};
    std::vector<Quat> qj(mc.clip.joints.size());
    std::vector<Vec3> pj(mc.clip.joints.size());
    auto qs = identity_quats();
    auto ps = zero_vec3s();
    KinematicPose pose;
    double worst_leg_m = 0;
    double worst_arm_m = 0;
    const auto at = [&](std::string_view seg) {
        return pose.joint_position_m[static_cast<std::size_t>(model.index_of(seg))];
    };
    const auto clip_at = [&](const std::string& joint) {
        return pj[static_cast<std::size_t>(mc.clip.index_of(joint))];
    };
    for (std::size_t f = 0; f < mc.clip.frame_count; f += 5) {
        bvh_global_pose(mc.clip, mc.clip.frame(f), 1.0, qj, pj);
        bvh_segment_pose(*mc.m.mapping, qj, pj, qs, ps);
        forward_kinematics(model, qs, ps[0], pose);
        for (const auto& [seg, joint] : legs)
            worst_leg_m = std::max(worst_leg_m, (at(seg) - clip_at(joint)).norm());
        for (std::size_t k = 0; k + 1 < arm_bones.size(); ++k) {
            if (k == 2) continue;  // the hand's end is not a listed joint
            const Vec3 ours = at(arm_bones[k + 1].first) - at(arm_bones[k].first);
            const Vec3 clip = clip_at(arm_bones[k + 1].second) - clip_at(arm_bones[k].second);
            worst_arm_m = std::max(worst_arm_m, (ours - clip).norm());
        }
    }
    EXPECT_LT(worst_leg_m, 1e-4);
    EXPECT_LT(worst_arm_m, 1e-4);
}

}  // namespace
}  // namespace mocap::skeleton
