// pose_encoder.cpp — one frame in, one shared length-prefixed buffer out.
#include "serve/pose_encoder.hpp"

#include <cassert>

#include "mocap/v1/mocap.pb.h"
#include "serve/framing.hpp"

namespace mocap::serve {

SharedBytes encode_server_message(const v1::ServerMessage& message) {
    auto out = std::make_shared<std::string>();
    if (!append_delimited(message, *out)) return nullptr;
    return out;
}

PoseEncoder::PoseEncoder() : message_(std::make_unique<v1::ServerMessage>()) {}
PoseEncoder::~PoseEncoder() = default;

SharedBytes PoseEncoder::encode_frame(const SubjectFrame& frame, const skeleton::SkeletonPose& pose,
                                      std::uint32_t fields, std::int64_t encoded_us) {
    fields = normalize_fields(fields);
    const std::uint32_t n = frame.segment_count;
    assert(n <= kMaxSegments);
    assert((fields & ~kFieldRaw) == 0 || pose.segment_count == n);

    // mutable_frame() keeps the existing sub-message; Clear() keeps repeated capacity.
    v1::SkeletonFrame* out = message_->mutable_frame();
    out->Clear();
    out->set_subject_id(frame.subject_id);
    out->set_sync(frame.sync);
    out->set_sample_us(frame.sample_us);
    v1::StageTimes* t = out->mutable_times();
    t->set_sink_send_us(frame.times.sink_send_us);
    t->set_received_us(frame.times.received_us);
    t->set_filtered_us(frame.times.filtered_us);
    t->set_assembled_us(frame.times.assembled_us);
    t->set_encoded_us(encoded_us);
    out->set_segment_count(n);

    auto* flags = out->mutable_flags();
    flags->Reserve(static_cast<int>(n));
    for (std::uint32_t i = 0; i < n; ++i) {
        const std::uint8_t extra = i < pose.segment_count ? pose.extra_flags[i] : 0;
        flags->AddAlreadyReserved(frame.segments[i].flags | extra);
    }
    auto put_quats = [n](google::protobuf::RepeatedField<float>* dst, auto&& quat_of) {
        dst->Reserve(static_cast<int>(4 * n));
        for (std::uint32_t i = 0; i < n; ++i) {
            const std::array<double, 4>& q = quat_of(i);
            for (double c : q)
                dst->AddAlreadyReserved(static_cast<float>(c));
        }
    };
    if (fields & kFieldOrientations) {
        put_quats(
            out->mutable_q_world_segment_wxyz(), [&](std::uint32_t i) -> const auto& {
                return pose.q_world_segment_wxyz[i];
            });
    }
    if (fields & kFieldPositions) {
        auto* dst = out->mutable_position_m();
        dst->Reserve(static_cast<int>(3 * n));
        for (std::uint32_t i = 0; i < n; ++i) {
            for (double c : pose.position_m[i])
                dst->AddAlreadyReserved(static_cast<float>(c));
        }
    }
    if (fields & kFieldJointAngles) {
        auto* dst = out->mutable_joint_angles_rad();
        const std::uint32_t count = pose.joint_angle_count;
        assert(count <= skeleton::kMaxJointAngles);
        dst->Reserve(static_cast<int>(count));
        for (std::uint32_t i = 0; i < count; ++i) {
            dst->AddAlreadyReserved(static_cast<float>(pose.joint_angles_rad[i]));
        }
    }
    if (fields & kFieldRaw) {
        put_quats(
            out->mutable_q_earth_sensor_wxyz(), [&](std::uint32_t i) -> const auto& {
                return frame.segments[i].q_earth_sensor_wxyz;
            });
    }
    return encode_server_message(*message_);
}

}  // namespace mocap::serve
