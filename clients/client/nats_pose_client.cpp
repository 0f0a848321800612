#include "nats_pose_client.hpp"

#include <nats/nats.h>

#include <algorithm>
#include <nlohmann/json.hpp>

namespace mocap::client {
namespace {

int64_t ms(std::chrono::milliseconds d) {
    return std::max<int64_t>(0, d.count());
}

// Keeps the fields a subscription selected (0 = orientations + positions, as the server
// normalises it); a cluster frame carries them all.
void select_fields(v1::SkeletonFrame& f, std::uint32_t fields) {
    fields &= 0xFu;
    if (fields == 0) fields = v1::FIELD_ORIENTATIONS | v1::FIELD_POSITIONS;
    if ((fields & v1::FIELD_ORIENTATIONS) == 0) f.clear_q_world_segment_wxyz();
    if ((fields & v1::FIELD_POSITIONS) == 0) f.clear_position_m();
    if ((fields & v1::FIELD_JOINT_ANGLES) == 0) f.clear_joint_angles_rad();
    if ((fields & v1::FIELD_RAW) == 0) f.clear_q_earth_sensor_wxyz();
}

}  // namespace

NatsPoseClient::~NatsPoseClient() {
    close();
}

void NatsPoseClient::close() {
    // The connection closes first, so its reader thread has stopped delivering before the
    // subscription is freed.
    if (connection_) natsConnection_Close(connection_);
    if (poses_) natsSubscription_Destroy(poses_);
    poses_ = nullptr;
    if (connection_) natsConnection_Destroy(connection_);
    connection_ = nullptr;
}

bool NatsPoseClient::connect(const NatsOptions& options, std::chrono::milliseconds timeout, std::string& error) {
    options_ = options;
    natsOptions* o = nullptr;
    natsStatus s = natsOptions_Create(&o);
    if (s == NATS_OK) s = natsOptions_SetURL(o, options.url.c_str());
    if (s == NATS_OK) s = natsOptions_SetTimeout(o, ms(timeout));
    if (s == NATS_OK && !options.user.empty())
        s = natsOptions_SetUserInfo(o, options.user.c_str(), options.password.c_str());
    if (s == NATS_OK && !options.creds_file.empty())
        s = natsOptions_SetUserCredentialsFromFiles(o, options.creds_file.c_str(), nullptr);
    if (s == NATS_OK) (void)natsOptions_SetMaxReconnect(o, -1);
    if (s == NATS_OK) s = natsConnection_Connect(&connection_, o);
    natsOptions_Destroy(o);
    if (s != NATS_OK) {
        error = "cannot connect to " + options.url + ": " + natsStatus_GetText(s);
        connection_ = nullptr;
        return false;
    }
    return true;
}

bool NatsPoseClient::subscribe(const SubscribeOptions& options, std::chrono::milliseconds heartbeat_wait,
                               std::string& error) {
    subscription_ = options;
    if (subscription_.decimation == 0) subscription_.decimation = 1;
    const std::string prefix = "mocap." + options_.site + ".";
    // One subscription: a single subject's pose subject, or the wildcard filtered here.
    const std::string subject = options.subject_ids.size() == 1
                                    ? prefix + std::to_string(options.subject_ids.front()) + ".pose"
                                    : prefix + "*.pose";
    natsSubscription* heartbeat = nullptr;
    natsStatus s = natsConnection_SubscribeSync(&heartbeat, connection_, (prefix + "host.*").c_str());
    if (s == NATS_OK) s = natsConnection_SubscribeSync(&poses_, connection_, subject.c_str());
    // Hold up to ~10 s of 100 Hz frames of 64 subjects before the library drops (counted).
    if (s == NATS_OK) s = natsSubscription_SetPendingLimits(poses_, 65536, 256 << 20);
    if (s == NATS_OK) s = natsConnection_FlushTimeout(connection_, 2000);
    if (s != NATS_OK) {
        natsSubscription_Destroy(heartbeat);
        error = "cannot subscribe to " + subject + ": " + natsStatus_GetText(s);
        return false;
    }
    natsMsg* msg = nullptr;
    if (natsSubscription_NextMsg(&msg, heartbeat, ms(heartbeat_wait)) == NATS_OK) {
        heartbeat_.assign(natsMsg_GetData(msg), static_cast<std::size_t>(natsMsg_GetDataLength(msg)));
        natsMsg_Destroy(msg);
        const auto j = nlohmann::json::parse(heartbeat_, nullptr, false);
        auto* skeleton = hello_.mutable_skeleton();
        if (j.is_object() && j.contains("segments") && j["segments"].is_array()) {
            for (const auto& name : j["segments"])
                if (name.is_string()) skeleton->add_segments()->set_name(name.get<std::string>());
        }
        if (j.is_object() && j.contains("joint_angle_names") && j["joint_angle_names"].is_array()) {
            for (const auto& name : j["joint_angle_names"])
                if (name.is_string()) skeleton->add_joint_angle_names(name.get<std::string>());
        }
        if (j.is_object() && j.contains("host_id") && j["host_id"].is_string())
            hello_.set_server_version("mocapd " + j["host_id"].get<std::string>() + " (NATS)");
    }
    natsSubscription_Destroy(heartbeat);
    return true;
}

ReadStatus NatsPoseClient::next_frame(v1::SkeletonFrame& out, std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    for (;;) {
        const auto left =
            std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
        natsMsg* msg = nullptr;
        const natsStatus s = natsSubscription_NextMsg(&msg, poses_, ms(left));
        if (s == NATS_TIMEOUT) return ReadStatus::kTimeout;
        if (s == NATS_CONNECTION_CLOSED || s == NATS_INVALID_SUBSCRIPTION) return ReadStatus::kClosed;
        if (s == NATS_SLOW_CONSUMER) continue;  // dropped frames: counted by drops_announced()
        if (s != NATS_OK) {
            error_ = natsStatus_GetText(s);
            return ReadStatus::kError;
        }
        last_receive_us_ = wall_clock_us();
        const bool parsed = scratch_.ParseFromArray(natsMsg_GetData(msg), natsMsg_GetDataLength(msg));
        natsMsg_Destroy(msg);
        if (!parsed || !scratch_.has_frame()) {
            error_ = "a message on a pose subject is not a mocap.v1.ServerMessage frame";
            return ReadStatus::kError;
        }
        v1::SkeletonFrame& f = *scratch_.mutable_frame();
        const auto& ids = subscription_.subject_ids;
        if (!ids.empty() && std::find(ids.begin(), ids.end(), f.subject_id()) == ids.end()) continue;
        if (seen_per_subject_[f.subject_id()]++ % subscription_.decimation != 0) continue;
        select_fields(f, subscription_.fields);
        out.Swap(&f);
        return ReadStatus::kMessage;
    }
}

std::uint64_t NatsPoseClient::drops_announced() const {
    int64_t dropped = 0;
    if (poses_) (void)natsSubscription_GetDropped(poses_, &dropped);
    return static_cast<std::uint64_t>(std::max<int64_t>(0, dropped));
}

}  // namespace mocap::client
