#include "output_commands.hpp"

#include <netdb.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include <cstdio>
#include <cstring>
#include <iostream>
#include <memory>
#include <sstream>

#include <nlohmann/json.hpp>

#include "core/errno_text.hpp"
#include "pose_client.hpp"
#include "serve/angles_csv.hpp"
#include "serve/bvh_frame_encoder.hpp"
#include "serve/bvh_text.hpp"
#include "serve/frame_interval.hpp"
#include "skeleton/euler.hpp"

namespace mocap::client {

namespace {

constexpr int kExitFailed = 1;
constexpr int kExitConnection = 2;
constexpr std::size_t kMaxHeaderBytes = 1u << 20;

int connect_blocking(const std::string& host, std::uint16_t port, std::chrono::milliseconds timeout,
                     std::string& error) {
    addrinfo hints{};
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_STREAM;
    addrinfo* found = nullptr;
    if (const int rc = getaddrinfo(host.c_str(), std::to_string(port).c_str(), &hints, &found); rc != 0) {
        error = "resolve " + host + ": " + gai_strerror(rc);
        return -1;
    }
    int fd = -1;
    for (addrinfo* ai = found; ai && fd < 0; ai = ai->ai_next) {
        fd = ::socket(ai->ai_family, ai->ai_socktype | SOCK_CLOEXEC, ai->ai_protocol);
        if (fd < 0) continue;
        timeval tv{static_cast<time_t>(timeout.count() / 1000),
                   static_cast<suseconds_t>((timeout.count() % 1000) * 1000)};
        ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
        ::setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
        if (::connect(fd, ai->ai_addr, ai->ai_addrlen) != 0) {
            error = std::string("connect: ") + errno_text(errno);
            ::close(fd);
            fd = -1;
        }
    }
    freeaddrinfo(found);
    if (fd < 0 && error.empty()) error = "connect " + host + ": no address";
    return fd;
}

std::FILE* create_new(const std::string& path) {
    return std::fopen(path.c_str(), "wx");
}

/// A complete BVH file: the hierarchy ("HIERARCHY" ... "}\n"), "MOTION", the frame count, the
/// "Frame Time:" line and the MOTION lines; refuses to overwrite a file.
int write_bvh_file(const ExportOptions& o, const std::string& hierarchy, const std::string& frame_time,
                   const std::vector<std::string>& lines, std::size_t values) {
    std::FILE* f = create_new(o.out);
    if (!f) {
        std::cerr << "mocap-client: cannot create " << o.out << " (it must not exist): " << errno_text(errno) << "\n";
        return kExitFailed;
    }
    std::string text = hierarchy + "MOTION\nFrames: " + std::to_string(lines.size()) + "\n" + frame_time;
    for (const auto& l : lines)
        text += l;
    const bool ok = std::fwrite(text.data(), 1, text.size(), f) == text.size();
    if (std::fclose(f) != 0 || !ok) {
        std::cerr << "mocap-client: writing " << o.out << " failed\n";
        return kExitFailed;
    }
    std::cout << o.out << ": " << lines.size() << " frames, " << values << " values per frame\n";
    return 0;
}

/// The live BVH encoding of the body a host heartbeat describes (docs/outputs.md, "Cluster
/// publisher"): the same model and options give the same HIERARCHY as the live port's.
std::unique_ptr<serve::BvhFrameEncoder> encoder_from_heartbeat(const std::string& text, std::string& error) {
    const auto j = nlohmann::json::parse(text, nullptr, false);
    if (!j.is_object() || !j.contains("body") || !j.contains("bvh")) {
        error = "the host heartbeat does not describe the body (a mocapd older than this client?)";
        return nullptr;
    }
    try {
        skeleton::BodyModel model;
        const auto vec3 = [](const nlohmann::json& v) {
            return skeleton::Vec3(v.at(0).get<double>(), v.at(1).get<double>(), v.at(2).get<double>());
        };
        for (const auto& s : j.at("body").at("segments")) {
            skeleton::SegmentDef d;
            d.name = s.at("name").get<std::string>();
            d.parent = s.at("parent").get<int>();
            d.offset_m = vec3(s.at("offset_m"));
            d.end_m = vec3(s.at("end_m"));
            model.segments.push_back(std::move(d));
        }
        model.root_height_m = j.at("body").at("root_height_m").get<double>();
        const auto& b = j.at("bvh");
        serve::BvhOutputOptions options;
        options.write.units_per_m = b.at("units_per_m").get<double>();
        options.write.decimals = b.at("decimals").get<int>();
        options.frame_time_s = b.at("frame_time_s").get<double>();
        const auto order = skeleton::parse_rotation_order(b.at("rotation_order").get<std::string>());
        if (!order) {
            error = "the host heartbeat names an unknown BVH rotation order";
            return nullptr;
        }
        options.write.order = *order;
        if (const auto problems = skeleton::validate(model); !problems.empty()) {
            error = "the host heartbeat's body: " + problems.front();
            return nullptr;
        }
        return std::make_unique<serve::BvhFrameEncoder>(std::move(model), options);
    } catch (const nlohmann::json::exception& e) {
        error = std::string("the host heartbeat's body: ") + e.what();
        return nullptr;
    }
}

}  // namespace

std::size_t bvh_channel_count(const std::string& hierarchy) {
    std::istringstream in(hierarchy);
    std::string token;
    std::size_t total = 0;
    while (in >> token) {
        if (token == "CHANNELS") {
            std::size_t n = 0;
            if (in >> n) total += n;
        }
    }
    return total;
}

int run_record_bvh(const ExportOptions& o) {
    std::string error;
    const int fd = connect_blocking(o.host, o.port, o.timeout, error);
    if (fd < 0) {
        std::cerr << "mocap-client: " << error << "\n";
        return kExitConnection;
    }
    std::unique_ptr<int, void (*)(int*)> guard(new int(fd), [](int* p) {
        ::close(*p);
        delete p;
    });
    if (o.subject != 0) {
        const std::string line = "subject " + std::to_string(o.subject) + "\n";
        if (::send(fd, line.data(), line.size(), MSG_NOSIGNAL) != static_cast<ssize_t>(line.size())) {
            std::cerr << "mocap-client: cannot send the subject selection\n";
            return kExitConnection;
        }
    }
    // Header: everything up to and including the "Frame Time:" line.
    std::string buf, header, frame_time;
    std::vector<std::string> lines;
    lines.reserve(o.frames);
    std::size_t values = 0;
    bool have_header = false;
    char chunk[65536];
    while (lines.size() < o.frames) {
        const ssize_t n = ::recv(fd, chunk, sizeof chunk, 0);
        if (n == 0) {
            std::cerr << "mocap-client: the server closed after " << lines.size() << " frames\n";
            return kExitConnection;
        }
        if (n < 0) {
            std::cerr << "mocap-client: " << (errno == EAGAIN ? "no data within the timeout" : errno_text(errno))
                      << "\n";
            return kExitConnection;
        }
        buf.append(chunk, static_cast<std::size_t>(n));
        std::size_t pos = 0;
        for (std::size_t nl; (nl = buf.find('\n', pos)) != std::string::npos && lines.size() < o.frames; pos = nl + 1) {
            std::string line = buf.substr(pos, nl + 1 - pos);
            if (!have_header) {
                if (line.rfind("Frame Time:", 0) == 0) {
                    frame_time = line;
                    have_header = true;
                    values = bvh_channel_count(header);
                    if (header.rfind("HIERARCHY", 0) != 0 || values == 0 || header.size() < 7 ||
                        header.compare(header.size() - 7, 7, "MOTION\n") != 0) {
                        std::cerr
                            << "mocap-client: not a live BVH stream (expected HIERARCHY ... MOTION, Frame Time)\n";
                        return kExitFailed;
                    }
                    header.resize(header.size() - 7);  // "MOTION\n" is written again with the count
                } else {
                    header += line;
                    if (header.size() > kMaxHeaderBytes) {
                        std::cerr << "mocap-client: BVH header longer than 1 MiB\n";
                        return kExitFailed;
                    }
                }
                continue;
            }
            const std::size_t count = serve::bvh_value_count(line);
            if (count != values) {
                std::cerr << "mocap-client: MOTION line " << lines.size() + 1 << " has " << count
                          << " values, the hierarchy declares " << values << "\n";
                return kExitFailed;
            }
            lines.push_back(std::move(line));
        }
        buf.erase(0, pos);
    }
    return write_bvh_file(o, header, frame_time, lines, values);
}

int run_record_bvh_nats(const NatsOptions& nats, const ExportOptions& o) {
    NatsPoseClient client;
    std::string error;
    if (!client.connect(nats, o.timeout, error)) {
        std::cerr << "mocap-client: " << error << "\n";
        return kExitConnection;
    }
    SubscribeOptions sub;
    if (o.subject != 0) sub.subject_ids.push_back(o.subject);
    sub.fields = v1::FIELD_ORIENTATIONS | v1::FIELD_POSITIONS;
    if (!client.subscribe(sub, o.timeout, error)) {
        std::cerr << "mocap-client: " << error << "\n";
        return kExitConnection;
    }
    if (client.heartbeat().empty()) {
        std::cerr << "mocap-client: no host heartbeat within the timeout: the body to write is unknown\n";
        return kExitConnection;
    }
    const auto encoder = encoder_from_heartbeat(client.heartbeat(), error);
    if (!encoder) {
        std::cerr << "mocap-client: " << error << "\n";
        return kExitFailed;
    }
    const std::size_t n = encoder->model().size();
    std::uint32_t subject = o.subject;  // 0: the subject of the first frame
    std::vector<std::string> lines;
    lines.reserve(o.frames);
    v1::SkeletonFrame frame;
    skeleton::SkeletonPose pose;
    serve::FrameInterval interval;  // Frame Time, unless the host configured one
    while (lines.size() < o.frames) {
        const ReadStatus s = client.next_frame(frame, o.timeout);
        if (s != ReadStatus::kMessage) {
            std::cerr << "mocap-client: "
                      << (s == ReadStatus::kTimeout ? "no frame within the timeout" : "connection ended") << " after "
                      << lines.size() << " frames\n";
            return kExitConnection;
        }
        if (subject == 0) subject = frame.subject_id();
        if (frame.subject_id() != subject) continue;
        if (frame.segment_count() != n || frame.q_world_segment_wxyz_size() != static_cast<int>(4 * n) ||
            frame.position_m_size() != static_cast<int>(3 * n)) {
            std::cerr << "mocap-client: frame has " << frame.segment_count() << " segments, the heartbeat's body " << n
                      << "\n";
            return kExitFailed;
        }
        pose.segment_count = static_cast<std::uint16_t>(n);
        for (std::size_t i = 0; i < n; ++i) {
            for (std::size_t k = 0; k < 4; ++k)
                pose.q_world_segment_wxyz[i][k] = frame.q_world_segment_wxyz(static_cast<int>(4 * i + k));
        }
        pose.position_m[0] = {frame.position_m(0), frame.position_m(1), frame.position_m(2)};
        interval.add(frame.sync(), frame.sample_us());
        std::string line;
        encoder->append_motion_line(pose, line);
        lines.push_back(std::move(line));
    }
    if (client.drops_announced() != 0) {
        std::cerr << "mocap-client: the client library dropped " << client.drops_announced() << " frame(s)\n";
    }
    // A single frame has no interval: the sinks' default rate (100 Hz) then.
    return write_bvh_file(o, encoder->hierarchy(), encoder->frame_time_line(interval.seconds().value_or(0.01)), lines,
                          encoder->values_per_frame());
}

int run_angles_csv(const ExportOptions& o) {
    PoseClient client;
    std::string error;
    if (!client.connect(o.host, o.port, o.timeout, error)) {
        std::cerr << "mocap-client: " << error << "\n";
        return kExitConnection;
    }
    SubscribeOptions sub;
    if (o.subject != 0) sub.subject_ids.push_back(o.subject);
    sub.fields = v1::FIELD_JOINT_ANGLES;
    if (!client.subscribe(sub, o.timeout, error)) {
        std::cerr << "mocap-client: " << error << "\n";
        return kExitConnection;
    }
    const auto& names = client.hello().skeleton().joint_angle_names();
    std::unique_ptr<std::FILE, int (*)(std::FILE*)> f(create_new(o.out), &std::fclose);
    if (!f) {
        std::cerr << "mocap-client: cannot create " << o.out << " (it must not exist): " << errno_text(errno) << "\n";
        return kExitFailed;
    }
    std::string text = serve::angles_csv_header(std::vector<std::string>(names.begin(), names.end()));
    v1::SkeletonFrame frame;
    std::uint64_t written = 0;
    while (written < o.frames) {
        const ReadStatus s = client.next_frame(frame, o.timeout);
        if (s != ReadStatus::kMessage) {
            std::cerr << "mocap-client: "
                      << (s == ReadStatus::kTimeout ? "no frame within the timeout" : "connection ended") << " after "
                      << written << " frames\n";
            return kExitConnection;
        }
        if (frame.joint_angles_rad_size() != names.size()) {
            std::cerr << "mocap-client: frame has " << frame.joint_angles_rad_size() << " joint angles, Hello names "
                      << names.size() << "\n";
            return kExitFailed;
        }
        serve::append_angles_csv_row(frame.subject_id(), frame.sync(), frame.sample_us(),
                                     frame.joint_angles_rad().data(),
                                     static_cast<std::size_t>(frame.joint_angles_rad_size()), text);
        ++written;
    }
    if (std::fwrite(text.data(), 1, text.size(), f.get()) != text.size() || std::fflush(f.get()) != 0) {
        std::cerr << "mocap-client: writing " << o.out << " failed\n";
        return kExitFailed;
    }
    if (client.drops_announced() != 0) {
        std::cerr << "mocap-client: the server dropped " << client.drops_announced() << " frame(s) for this client\n";
    }
    std::cout << o.out << ": " << written << " frames, " << names.size() << " angles per frame\n";
    return 0;
}

}  // namespace mocap::client
