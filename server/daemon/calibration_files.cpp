#include "daemon/calibration_files.hpp"

#include <spdlog/spdlog.h>

#include <filesystem>
#include <fstream>
#include <sstream>

namespace mocap::daemon {

namespace fs = std::filesystem;

std::string CalibrationFiles::path(std::uint32_t subject_id) const {
    return (fs::path(dir_) / ("calibration-subject-" + std::to_string(subject_id) + ".toml")).string();
}

skeleton::StoredCalibration CalibrationFiles::load(const skeleton::BodyModel& model, std::uint32_t subject_id) {
    skeleton::StoredCalibration out;
    out.where = path(subject_id);
    std::error_code ec;
    if (!fs::exists(out.where, ec)) return out;
    std::ifstream in(out.where);
    std::stringstream text;
    text << in.rdbuf();
    auto r = skeleton::parse_calibration(model, text.str());
    out.calibration = std::move(r.calibration);
    out.error = std::move(r.error);
    return out;
}

std::string CalibrationFiles::save(const skeleton::BodyModel& model, std::uint32_t subject_id,
                                   const skeleton::Calibration& calibration) {
    const std::string file = path(subject_id);
    const std::string tmp = file + ".tmp";
    {
        std::ofstream out(tmp, std::ios::trunc);
        out << skeleton::serialize_calibration(model, calibration);
        if (!out) return "cannot write " + tmp;
    }
    std::error_code ec;
    fs::rename(tmp, file, ec);  // atomic replace: a crash never leaves half a file
    if (ec) return "cannot save calibration to " + file + ": " + ec.message();
    return {};
}

std::unique_ptr<skeleton::CalibrationStore> calibration_files(const std::string& dir) {
    if (dir.empty()) return nullptr;
    return std::make_unique<CalibrationFiles>(dir);
}

void log_to_spdlog(skeleton::LogLevel level, const std::string& line) {
    switch (level) {
        case skeleton::LogLevel::kDebug:
            spdlog::debug("{}", line);
            break;
        case skeleton::LogLevel::kInfo:
            spdlog::info("{}", line);
            break;
        case skeleton::LogLevel::kWarn:
            spdlog::warn("{}", line);
            break;
        case skeleton::LogLevel::kError:
            spdlog::error("{}", line);
            break;
    }
}

}  // namespace mocap::daemon
