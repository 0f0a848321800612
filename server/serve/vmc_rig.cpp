#include "serve/vmc_rig.hpp"

#include <algorithm>

namespace mocap::serve {
namespace {

// Unity's HumanBodyBones in enum order with the humanoid parent of each (HumanTrait's
// hierarchy; UpperChest, added last to the enum, sits between Chest and Neck/shoulders).
constexpr int kUpperChest = 54;
constexpr HumanoidBone kBones[] = {
    {"Hips", -1},
    {"LeftUpperLeg", 0},
    {"RightUpperLeg", 0},
    {"LeftLowerLeg", 1},
    {"RightLowerLeg", 2},
    {"LeftFoot", 3},
    {"RightFoot", 4},
    {"Spine", 0},
    {"Chest", 7},
    {"Neck", kUpperChest},
    {"Head", 9},
    {"LeftShoulder", kUpperChest},
    {"RightShoulder", kUpperChest},
    {"LeftUpperArm", 11},
    {"RightUpperArm", 12},
    {"LeftLowerArm", 13},
    {"RightLowerArm", 14},
    {"LeftHand", 15},
    {"RightHand", 16},
    {"LeftToes", 5},
    {"RightToes", 6},
    {"LeftEye", 10},
    {"RightEye", 10},
    {"Jaw", 10},
    {"LeftThumbProximal", 17},
    {"LeftThumbIntermediate", 24},
    {"LeftThumbDistal", 25},
    {"LeftIndexProximal", 17},
    {"LeftIndexIntermediate", 27},
    {"LeftIndexDistal", 28},
    {"LeftMiddleProximal", 17},
    {"LeftMiddleIntermediate", 30},
    {"LeftMiddleDistal", 31},
    {"LeftRingProximal", 17},
    {"LeftRingIntermediate", 33},
    {"LeftRingDistal", 34},
    {"LeftLittleProximal", 17},
    {"LeftLittleIntermediate", 36},
    {"LeftLittleDistal", 37},
    {"RightThumbProximal", 18},
    {"RightThumbIntermediate", 39},
    {"RightThumbDistal", 40},
    {"RightIndexProximal", 18},
    {"RightIndexIntermediate", 42},
    {"RightIndexDistal", 43},
    {"RightMiddleProximal", 18},
    {"RightMiddleIntermediate", 45},
    {"RightMiddleDistal", 46},
    {"RightRingProximal", 18},
    {"RightRingIntermediate", 48},
    {"RightRingDistal", 49},
    {"RightLittleProximal", 18},
    {"RightLittleIntermediate", 51},
    {"RightLittleDistal", 52},
    {"UpperChest", 8},
};

constexpr std::pair<std::string_view, std::string_view> kDefaultMap[] = {
    {skeleton::seg::kPelvis, "Hips"},
    {skeleton::seg::kTrunk, "Spine"},
    {skeleton::seg::kHead, "Head"},
    {skeleton::seg::kLeftUpperArm, "LeftUpperArm"},
    {skeleton::seg::kLeftForearm, "LeftLowerArm"},
    {skeleton::seg::kLeftHand, "LeftHand"},
    {skeleton::seg::kRightUpperArm, "RightUpperArm"},
    {skeleton::seg::kRightForearm, "RightLowerArm"},
    {skeleton::seg::kRightHand, "RightHand"},
    {skeleton::seg::kLeftThigh, "LeftUpperLeg"},
    {skeleton::seg::kLeftCalf, "LeftLowerLeg"},
    {skeleton::seg::kLeftFoot, "LeftFoot"},
    {skeleton::seg::kRightThigh, "RightUpperLeg"},
    {skeleton::seg::kRightCalf, "RightLowerLeg"},
    {skeleton::seg::kRightFoot, "RightFoot"},
};

VmcBonePose bone_pose(const math::Vec3& position_unity, const math::Quat& q_unity) {
    return {{static_cast<float>(position_unity.x()), static_cast<float>(position_unity.y()),
             static_cast<float>(position_unity.z())},
            {static_cast<float>(q_unity.x()), static_cast<float>(q_unity.y()), static_cast<float>(q_unity.z()),
             static_cast<float>(q_unity.w())}};
}

math::Quat quat_of(const std::array<double, 4>& wxyz) {
    return {wxyz[0], wxyz[1], wxyz[2], wxyz[3]};
}

}  // namespace

std::span<const HumanoidBone> humanoid_bones() {
    return kBones;
}

int humanoid_bone_index(std::string_view name) {
    for (std::size_t i = 0; i < std::size(kBones); ++i) {
        if (kBones[i].name == name) return static_cast<int>(i);
    }
    return -1;
}

std::span<const std::pair<std::string_view, std::string_view>> default_humanoid_map() {
    return kDefaultMap;
}

math::Vec3 unity_from_body(const math::Vec3& v) {
    return {-v.y(), v.z(), v.x()};
}

math::Quat unity_from_body(const math::Quat& q) {
    return {q.w(), q.y(), -q.z(), -q.x()};
}

std::optional<VmcRig> VmcRig::build(const skeleton::BodyModel& model,
                                    const std::vector<std::pair<std::string, std::string>>& map, std::string* error) {
    std::vector<int> bone_of(model.size(), -1);  // segment -> humanoid bone
    const auto assign = [&](std::string_view segment, std::string_view bone, bool configured) {
        const int s = model.index_of(segment);
        const std::string key = "vmc.bones." + std::string(segment);
        if (s < 0) {
            if (!configured) return true;  // a default name the custom model lacks
            *error = key + ": the body model has no segment \"" + std::string(segment) + "\"";
            return false;
        }
        const int b = humanoid_bone_index(bone);
        if (b < 0) {
            *error = key + ": \"" + std::string(bone) +
                     "\" is not a Unity HumanBodyBones name (Hips, Spine, Chest, UpperChest, Neck, Head, "
                     "LeftUpperArm, ...)";
            return false;
        }
        if (const auto other = std::find(bone_of.begin(), bone_of.end(), b); other != bone_of.end()) {
            *error = key + ": bone " + std::string(bone) + " is already carried by segment \"" +
                     model.segments[static_cast<std::size_t>(other - bone_of.begin())].name + "\"";
            return false;
        }
        bone_of[static_cast<std::size_t>(s)] = b;
        return true;
    };
    if (map.empty()) {
        for (const auto& [segment, bone] : kDefaultMap) {
            if (!assign(segment, bone, false)) return std::nullopt;
        }
    } else {
        for (const auto& [segment, bone] : map) {
            if (!assign(segment, bone, true)) return std::nullopt;
        }
    }
    if (bone_of[0] != 0) {
        *error = "vmc.bones: the root segment \"" + model.segments[0].name + "\" must carry Hips (set vmc.bones." +
                 model.segments[0].name + " = \"Hips\")";
        return std::nullopt;
    }

    VmcRig rig;
    for (std::size_t s = 0; s < model.size(); ++s) {
        const int b = bone_of[s];
        if (b < 0) {
            rig.skipped_.push_back(model.segments[s].name);
            continue;
        }
        Bone bone;
        bone.segment = static_cast<int>(s);
        bone.bone = b;
        if (s != 0) {
            // Rest offset from the nearest mapped ancestor: every frame is the body frame at
            // rest, so the offsets along the chain add up in the ancestor's frame.
            math::Vec3 offset = model.segments[s].offset_m;
            int a = model.segments[s].parent;
            while (bone_of[static_cast<std::size_t>(a)] < 0) {
                offset += model.segments[static_cast<std::size_t>(a)].offset_m;
                a = model.segments[static_cast<std::size_t>(a)].parent;
            }
            int h = kBones[b].parent;  // nearest humanoid ancestor that some segment carries
            while (h >= 0 && std::find(bone_of.begin(), bone_of.end(), h) == bone_of.end())
                h = kBones[h].parent;
            if (h != bone_of[static_cast<std::size_t>(a)]) {
                *error = "vmc.bones." + model.segments[s].name + ": " + std::string(kBones[b].name) + " is not below " +
                         std::string(kBones[bone_of[static_cast<std::size_t>(a)]].name) +
                         " (the bone of its nearest mapped ancestor segment \"" +
                         model.segments[static_cast<std::size_t>(a)].name +
                         "\") in Unity's humanoid hierarchy; its nearest mapped humanoid ancestor is " +
                         (h >= 0 ? std::string(kBones[h].name) : std::string("none"));
                return std::nullopt;
            }
            bone.ancestor = a;
            bone.rest = bone_pose(unity_from_body(offset), math::Quat::Identity());
        }
        rig.bones_.push_back(bone);
    }
    return rig;
}

void VmcRig::convert(const skeleton::SkeletonPose& pose, VmcPose& out) const {
    const math::Vec3 pelvis = unity_from_body(math::to_vec3(pose.position_m[0]));
    out.root = bone_pose({pelvis.x(), 0.0, pelvis.z()}, math::Quat::Identity());
    out.bone_count = bones_.size();
    for (std::size_t i = 0; i < bones_.size(); ++i) {
        const Bone& b = bones_[i];
        const math::Quat q_world = quat_of(pose.q_world_segment_wxyz[static_cast<std::size_t>(b.segment)]);
        if (b.ancestor < 0) {
            out.bones[i] = bone_pose({0.0, pelvis.y(), 0.0}, unity_from_body(q_world));
            continue;
        }
        const math::Quat q_ancestor = quat_of(pose.q_world_segment_wxyz[static_cast<std::size_t>(b.ancestor)]);
        out.bones[i] = b.rest;
        out.bones[i].rotation_xyzw =
            bone_pose(math::Vec3::Zero(), unity_from_body(q_ancestor.conjugate() * q_world)).rotation_xyzw;
    }
}

}  // namespace mocap::serve
