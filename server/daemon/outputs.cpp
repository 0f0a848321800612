#include "daemon/outputs.hpp"

#include <spdlog/spdlog.h>

#include <fcntl.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <limits>

#include "cluster/cluster_publisher.hpp"
#include "daemon/peer_limits.hpp"
#include "daemon/pipeline_config.hpp"
#include "serve/angles_csv.hpp"
#include "serve/bvh_server.hpp"
#include "serve/raw_recorder.hpp"
#include "serve/vmc_sender.hpp"

namespace mocap::daemon {

namespace {

/// A network server as an output: frames go to publish(), which never blocks; start() binds,
/// stop() closes every client. `Server` is serve::PoseServer or serve::BvhServer.
template <class Server>
class ServerOutput : public pipeline::Output {
public:
    template <class... Args>
    explicit ServerOutput(Args&&... args) : server_(std::forward<Args>(args)...) {}
    bool start(std::string* error) override { return server_.start(*error); }
    bool stop(std::string* /*error*/) override {
        server_.stop();
        return true;
    }
    void on_frame(const SubjectFrame& frame, const skeleton::SkeletonPose& pose) override {
        server_.publish(frame, pose);
    }
    void register_metrics(MetricsRegistry& registry) const override { server_.register_metrics(registry); }
    [[nodiscard]] std::uint16_t port() const override { return server_.port(); }

protected:
    Server server_;
};

/// The protobuf pose service (serve/pose_server.hpp), [serve]: also the control and Stats
/// endpoint.
class PoseServiceOutput final : public ServerOutput<serve::PoseServer> {
public:
    PoseServiceOutput(const serve::ServeConfig& config, const serve::ControlHandlers& handlers,
                      const serve::ServeDescription& description)
        : ServerOutput(config, handlers) {
        server_.set_description(description);
    }
    [[nodiscard]] std::string_view name() const override { return "pose"; }
    [[nodiscard]] std::vector<Heartbeat> heartbeats() const override { return server_.heartbeats(); }
};

/// Holds the BVH encoder in a base class, so it is built before the server that refers to it
/// (bases are initialised in declaration order, before members).
struct BvhEncoderHolder {
    serve::BvhFrameEncoder encoder;
};

/// Live BVH text over TCP (serve/bvh_server.hpp), [outputs].bvh_live.
class BvhLiveOutput final : private BvhEncoderHolder, public ServerOutput<serve::BvhServer> {
public:
    BvhLiveOutput(const serve::BvhServerConfig& config, const skeleton::BodyModel& model,
                  const serve::BvhOutputOptions& options)
        : BvhEncoderHolder{serve::BvhFrameEncoder(model, options)}, ServerOutput(config, encoder) {}
    [[nodiscard]] std::string_view name() const override { return "bvh_live"; }
};

/// Every received sample to rotating raw files (serve/raw_recorder.hpp), [outputs].raw_record.
class RawRecorderOutput final : public pipeline::Output {
public:
    RawRecorderOutput(const serve::RawRecorderConfig& config, const Clock& clock) : recorder_(config, clock) {}
    [[nodiscard]] std::string_view name() const override { return "raw_record"; }
    bool start(std::string* error) override { return recorder_.start(error); }
    bool stop(std::string* /*error*/) override {
        recorder_.stop();  // ingest, its producer, has stopped
        return true;
    }
    void on_frame(const SubjectFrame& /*frame*/, const skeleton::SkeletonPose& /*pose*/) override {}
    [[nodiscard]] bool wants_samples() const override { return true; }
    void on_sample(const SegmentSample& sample) override { recorder_.push(sample); }
    void register_metrics(MetricsRegistry& registry) const override { recorder_.register_metrics(registry); }

private:
    serve::RawRecorder recorder_;
};

/// An output whose configuration turned out unusable when it was built: start() refuses with
/// the reason, so the daemon does not start.
class RefusedOutput final : public pipeline::Output {
public:
    RefusedOutput(std::string name, std::string reason) : name_(std::move(name)), reason_(std::move(reason)) {}
    [[nodiscard]] std::string_view name() const override { return name_; }
    bool start(std::string* error) override {
        *error = name_ + ": " + reason_;
        return false;
    }
    bool stop(std::string* /*error*/) override { return true; }
    void on_frame(const SubjectFrame& /*frame*/, const skeleton::SkeletonPose& /*pose*/) override {}

private:
    std::string name_;
    std::string reason_;
};

/// One subject as the VMC protocol over UDP (serve/vmc_sender.hpp), [vmc].
class VmcOutput final : public pipeline::Output {
public:
    VmcOutput(serve::VmcSenderConfig config, serve::VmcRig rig, const Clock& clock)
        : sender_(std::move(config), std::move(rig), clock) {}
    [[nodiscard]] std::string_view name() const override { return "vmc"; }
    bool start(std::string* /*error*/) override {
        sender_.start();
        return true;
    }
    bool stop(std::string* /*error*/) override {
        sender_.stop();
        return true;
    }
    void on_frame(const SubjectFrame& frame, const skeleton::SkeletonPose& pose) override {
        sender_.publish(frame, pose);
    }
    void register_metrics(MetricsRegistry& registry) const override { sender_.register_metrics(registry); }

private:
    serve::VmcSender sender_;
};

/// Viewer page, WebSocket poses, /metrics, /healthz, control over HTTP (serve/http_server.hpp),
/// [http]. An aid, not the pose service: a taken port is logged and the endpoint stays off.
class HttpOutput final : public pipeline::Output {
public:
    explicit HttpOutput(std::unique_ptr<serve::HttpServer> server) : server_(std::move(server)) {}
    [[nodiscard]] std::string_view name() const override { return "http"; }
    bool start(std::string* /*error*/) override {
        std::string http_error;
        if (!server_->start(http_error)) {
            spdlog::error("{}; the viewer, /metrics and /healthz are off", http_error);
            off_ = true;
        }
        return true;
    }
    bool stop(std::string* /*error*/) override {
        server_->stop();
        return true;
    }
    void on_frame(const SubjectFrame& frame, const skeleton::SkeletonPose& pose) override {
        if (!off_) server_->publish(frame, pose);
    }
    void register_metrics(MetricsRegistry& registry) const override { server_->register_metrics(registry); }
    [[nodiscard]] std::uint16_t port() const override { return off_ ? 0 : server_->port(); }
    [[nodiscard]] std::int64_t last_frame_us() const override { return off_ ? 0 : server_->last_frame_us(); }

private:
    std::unique_ptr<serve::HttpServer> server_;
    bool off_ = false;  // set once in start(), before frames flow
};

/// Joint angles, one CSV row per frame (serve/angles_csv.hpp): replay's --angles-out.
class AnglesCsvOutput final : public pipeline::Output {
public:
    /// fd >= 0: write into that open file (through a dup), `path` only names it.
    AnglesCsvOutput(std::string path, int fd, std::vector<std::string> angle_names)
        : path_(fd >= 0 && path.empty() ? "the CSV export" : std::move(path)),
          fd_(fd),
          angle_names_(std::move(angle_names)) {}
    [[nodiscard]] std::string_view name() const override { return "angles_csv"; }
    bool start(std::string* error) override {
        if (fd_ >= 0) {
            const int own = ::fcntl(fd_, F_DUPFD_CLOEXEC, 0);
            file_.reset(own < 0 ? nullptr : ::fdopen(own, "w"));
            if (!file_) {
                if (own >= 0) ::close(own);
                *error = "cannot write " + path_;
                return false;
            }
        } else {
            file_.reset(std::fopen(path_.c_str(), "wx"));
        }
        if (!file_) {
            *error = "cannot create " + path_ + " (it must not exist)";
            return false;
        }
        const std::string header = serve::angles_csv_header(angle_names_);
        (void)std::fwrite(header.data(), 1, header.size(), file_.get());  // checked in stop()
        return true;
    }
    bool stop(std::string* error) override {
        // fflush alone misses a write that failed earlier (ENOSPC while a full buffer went
        // out): the stream's error flag keeps it.
        if (file_ && (std::fflush(file_.get()) != 0 || std::ferror(file_.get()) != 0)) {
            *error = "write " + path_ + " failed";
            return false;
        }
        return true;
    }
    void on_frame(const SubjectFrame& f, const skeleton::SkeletonPose& p) override {
        row_.clear();
        serve::append_angles_csv_row(f.subject_id, f.sync, f.sample_us, p.joint_angles_rad.data(), p.joint_angle_count,
                                     row_);
        // A failed write sets the stream's error flag, checked once in stop().
        (void)std::fwrite(row_.data(), 1, row_.size(), file_.get());
    }

private:
    std::string path_;
    int fd_ = -1;
    std::vector<std::string> angle_names_;
    std::unique_ptr<std::FILE, int (*)(std::FILE*)> file_{nullptr, &std::fclose};
    std::string row_;
};

std::vector<std::string> joint_angle_names(const pipeline::Pipeline& p) {
    std::vector<std::string> names;
    for (const auto& j : p.solver().joints()) {
        for (const char* axis : {"flexion", "abduction", "rotation"})
            names.push_back(j.name + "." + axis);
    }
    return names;
}

// --- factories: each reads its config section and returns the output or nothing ---

std::unique_ptr<pipeline::Output> make_pose_service(const OutputContext& ctx) {
    if (ctx.replay) return nullptr;
    const DaemonConfig& c = ctx.config;
    serve::ServeConfig sc;
    sc.bind_address = c.pose_listen.host;
    sc.port = c.pose_listen.port;
    sc.max_clients = c.max_clients;
    sc.limits = peer_limits(c, c.pose_per_address);
    sc.queue_frames = c.client_queue_frames;
    sc.subscribe_timeout_ms = static_cast<std::uint32_t>(c.handshake_timeout_s * 1000.0);
    sc.max_client_message_bytes = c.max_message_bytes;
    sc.max_client_messages_per_s = c.max_client_messages_per_s;
    sc.client_message_burst = c.client_message_burst;
    sc.max_address_messages_per_s = c.max_address_messages_per_s;
    sc.address_message_burst = c.address_message_burst;
    sc.max_subscribe_subjects = c.max_subscribe_subjects;
    sc.control_token = c.control_token;
    sc.control_loopback_only = c.control_loopback_only;
    sc.control_attempts = ctx.control_attempts;
    sc.io_threads = c.serve_threads;
    sc.wall_clock_us = [&clock = ctx.clock] { return clock.now_us(); };
    sc.server_version = "mocapd";

    serve::ServeDescription desc;
    for (const auto& s : ctx.pipeline.model().segments) {
        desc.segments.push_back({s.name,
                                 s.parent,
                                 {s.offset_m.x(), s.offset_m.y(), s.offset_m.z()},
                                 static_cast<std::uint32_t>(std::max(0, s.node_id))});
    }
    desc.joint_angle_names = joint_angle_names(ctx.pipeline);
    for (std::uint32_t id : ctx.pipeline.subjects())
        desc.subjects.push_back({id, "subject-" + std::to_string(id)});
    return std::make_unique<PoseServiceOutput>(sc, ctx.control, desc);
}

std::unique_ptr<pipeline::Output> make_bvh_live(const OutputContext& ctx) {
    if (ctx.replay || !ctx.config.bvh_live) return nullptr;
    serve::BvhServerConfig bc;
    bc.bind_address = ctx.config.bvh_listen.host;
    bc.port = ctx.config.bvh_listen.port;
    bc.max_clients = ctx.config.bvh_max_clients;
    bc.threads = ctx.config.bvh_threads;
    bc.queue_frames = ctx.config.client_queue_frames;
    bc.subject = ctx.config.bvh_subject;
    bc.limits = peer_limits(ctx.config, ctx.config.bvh_per_address);
    return std::make_unique<BvhLiveOutput>(bc, ctx.pipeline.model(), bvh_options_from_config(ctx.config));
}

std::unique_ptr<pipeline::Output> make_bvh_recorder(const OutputContext& ctx) {
    serve::BvhRecorderConfig rc;
    rc.directory = ctx.config.record_dir;
    rc.subject = ctx.config.bvh_subject;
    rc.flush_interval_s = ctx.config.record_flush_interval_s;
    std::string start_path;
    if (ctx.replay) {
        if (ctx.replay->bvh_out.empty() && ctx.replay->bvh_out_fd < 0) return nullptr;
        if (ctx.replay->bvh_subject != 0) rc.subject = ctx.replay->bvh_subject;
        rc.max_buffer_bytes = std::numeric_limits<std::size_t>::max();  // never drop: the file must be complete
        start_path = ctx.replay->bvh_out;
    }
    const int start_fd = ctx.replay ? ctx.replay->bvh_out_fd : -1;
    if (start_fd >= 0 && start_path.empty()) start_path = "the BVH export";
    return std::make_unique<BvhRecorderOutput>(rc, ctx.pipeline.model(), bvh_options_from_config(ctx.config),
                                               std::move(start_path), start_fd);
}

std::unique_ptr<pipeline::Output> make_raw_recorder(const OutputContext& ctx) {
    if (ctx.replay || !ctx.config.raw_record) return nullptr;
    serve::RawRecorderConfig rrc;
    rrc.directory = ctx.config.record_dir;
    rrc.flush_interval_s = ctx.config.record_flush_interval_s;
    rrc.rotate_bytes = static_cast<std::uint64_t>(ctx.config.raw_rotate_mb * 1024.0 * 1024.0);
    rrc.rotate_s = ctx.config.raw_rotate_s;
    rrc.ring_capacity = ctx.config.raw_ring_capacity;
    return std::make_unique<RawRecorderOutput>(rrc, ctx.clock);
}

std::unique_ptr<pipeline::Output> make_take_recorder(const OutputContext& ctx) {
    if (ctx.replay || !ctx.takes) return nullptr;
    serve::TakeRecorderConfig tc;
    tc.raw.flush_interval_s = ctx.config.record_flush_interval_s;
    tc.raw.ring_capacity = ctx.config.raw_ring_capacity;
    tc.filter = ctx.config.filter_name;
    tc.calibration_dir = ctx.config.calibration_dir;
    tc.min_free_bytes = static_cast<std::uint64_t>(ctx.config.take_start_min_free_mb * 1024.0 * 1024.0);
    return std::make_unique<TakeRecorderOutput>(*ctx.takes, tc, ctx.clock);
}

std::unique_ptr<pipeline::Output> make_angles_csv(const OutputContext& ctx) {
    if (!ctx.replay || (ctx.replay->angles_out.empty() && ctx.replay->angles_out_fd < 0)) return nullptr;
    return std::make_unique<AnglesCsvOutput>(ctx.replay->angles_out, ctx.replay->angles_out_fd,
                                             joint_angle_names(ctx.pipeline));
}

// The names a browser may have used to reach this machine besides IP literals: localhost,
// this host's name (and its mDNS form) and the operator's list.
std::vector<std::string> http_allowed_hosts(const DaemonConfig& config) {
    std::vector<std::string> names{"localhost"};
    std::array<char, 256> host{};
    if (::gethostname(host.data(), host.size() - 1) == 0 && host[0] != '\0') {
        names.emplace_back(host.data());
        names.push_back(std::string(host.data()) + ".local");
    }
    names.insert(names.end(), config.http_allowed_hosts.begin(), config.http_allowed_hosts.end());
    return names;
}

std::unique_ptr<pipeline::Output> make_http(const OutputContext& ctx) {
    if (ctx.replay || !ctx.config.http_enabled) return nullptr;
    serve::HttpServerConfig hc;
    hc.bind_address = ctx.config.http_listen.host;
    hc.port = ctx.config.http_listen.port;
    hc.max_clients = ctx.config.http_max_clients;
    hc.threads = ctx.config.http_threads;
    hc.ws_queue_frames = ctx.config.http_ws_queue_frames;
    hc.control_token = ctx.config.control_token;
    hc.control_loopback_only = ctx.config.control_loopback_only;
    hc.allowed_origins = ctx.config.http_allowed_origins;
    hc.allowed_hosts = http_allowed_hosts(ctx.config);
    hc.limits = peer_limits(ctx.config, ctx.config.http_per_address);
    hc.export_memory_bytes = std::uint64_t{ctx.config.export_memory_mb} << 20;
    hc.export_memory_per_address_bytes = std::uint64_t{ctx.config.export_memory_per_address_mb} << 20;
    hc.control_attempts = ctx.control_attempts;
    hc.wall_clock_us = [&clock = ctx.clock] { return clock.now_us(); };
    serve::HttpDescription hd;
    for (const auto& seg : ctx.pipeline.model().segments)
        hd.segments.push_back({seg.name, seg.parent, {seg.end_m.x(), seg.end_m.y(), seg.end_m.z()}});
    hd.subjects = ctx.pipeline.subjects();
    serve::HttpHandlers hh;
    hh.control = ctx.control;
    hh.metrics = ctx.metrics;
    hh.health = ctx.health;
    hh.takes = ctx.takes;
    hh.export_take = ctx.export_take;
    return std::make_unique<HttpOutput>(
        std::make_unique<serve::HttpServer>(std::move(hc), std::move(hd), std::move(hh)));
}

std::unique_ptr<pipeline::Output> make_cluster(const OutputContext& ctx) {
    const DaemonConfig& c = ctx.config;
    if (ctx.replay || c.cluster_nats_url.empty()) return nullptr;
    cluster::ClusterConfig cc = cluster_config_from_config(c);
    cc.wall_clock_us = [&clock = ctx.clock] { return clock.now_us(); };
    for (const auto& s : ctx.pipeline.model().segments)
        cc.segment_names.push_back(s.name);
    cc.joint_angle_names = joint_angle_names(ctx.pipeline);
    cc.model = ctx.pipeline.model();
    cc.bvh = bvh_options_from_config(c);
    return std::make_unique<cluster::ClusterPublisher>(std::move(cc));
}

std::unique_ptr<pipeline::Output> make_vmc(const OutputContext& ctx) {
    const DaemonConfig& c = ctx.config;
    if (ctx.replay || !c.vmc_enabled) return nullptr;
    serve::VmcSenderConfig vc;
    vc.subject = c.vmc_subject;
    for (const auto& text : c.vmc_destinations) {
        std::string err;
        const auto ep = parse_destination(text, &err);  // checked by check_config
        if (ep) vc.destinations.push_back({ep->host, ep->port});
    }
    std::string err;
    auto rig = serve::VmcRig::build(ctx.pipeline.model(), c.vmc_bones, &err);
    if (!rig) return std::make_unique<RefusedOutput>("vmc", err);  // check_config refuses such a config first
    return std::make_unique<VmcOutput>(std::move(vc), std::move(*rig), ctx.clock);
}

// The registry: one line per output, in the order they receive frames.
constexpr OutputEntry kOutputs[] = {
    {"pose", &make_pose_service},          // [pose] protobuf pose service (always on live)
    {"bvh_live", &make_bvh_live},          // [outputs].bvh_live
    {"bvh_record", &make_bvh_recorder},    // [outputs].record_dir (live, by control); --bvh-out (replay)
    {"raw_record", &make_raw_recorder},    // [outputs].raw_record
    {"take_record", &make_take_recorder},  // live: takes in <record_dir>/takes, by control
    {"angles_csv", &make_angles_csv},      // --angles-out (replay)
    {"http", &make_http},                  // [http].enabled
    {"cluster", &make_cluster},            // [cluster].nats_url
    {"vmc", &make_vmc},                    // [vmc].enabled
};

}  // namespace

BvhRecorderOutput::BvhRecorderOutput(const serve::BvhRecorderConfig& config, const skeleton::BodyModel& model,
                                     const serve::BvhOutputOptions& options, std::string start_path, int start_fd)
    : encoder_(model, options), recorder_(config, encoder_), start_path_(std::move(start_path)), start_fd_(start_fd) {}

bool BvhRecorderOutput::start(std::string* error) {
    if (start_fd_ >= 0) return recorder_.start_fd(start_fd_, start_path_, error);
    return start_path_.empty() || recorder_.start(start_path_, error);
}

bool BvhRecorderOutput::stop(std::string* error) {
    if (!recorder_.has_file()) return true;
    return recorder_.stop(error, &frames_written_);  // patches the frame count; false after a write failure
}

std::span<const OutputEntry> output_registry() {
    return kOutputs;
}

void add_outputs(const OutputContext& context, pipeline::Pipeline& pipeline) {
    for (const auto& entry : output_registry()) {
        if (auto output = entry.make(context)) pipeline.add_output(std::move(output));
    }
}

}  // namespace mocap::daemon
