// calibration_files.hpp — the daemon's CalibrationStore: one TOML file per subject,
// <dir>/calibration-subject-<id>.toml, in the text form of skeleton/calibration.hpp.
// Saving writes <file>.tmp and renames it over the file, so a crash never leaves half a
// file. Used by the live daemon and by `mocapd --replay --calibration-dir`.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "skeleton/calibration_store.hpp"
#include "skeleton/pose_solver.hpp"

namespace mocap::daemon {

class CalibrationFiles final : public skeleton::CalibrationStore {
public:
    explicit CalibrationFiles(std::string dir) : dir_(std::move(dir)) {}

    skeleton::StoredCalibration load(const skeleton::BodyModel& model, std::uint32_t subject_id) override;
    std::string save(const skeleton::BodyModel& model, std::uint32_t subject_id,
                     const skeleton::Calibration& calibration) override;

    [[nodiscard]] std::string path(std::uint32_t subject_id) const;

private:
    std::string dir_;
};

/// The file store for dir, or nullptr for "" (calibrations neither loaded nor saved).
std::unique_ptr<skeleton::CalibrationStore> calibration_files(const std::string& dir);

/// The solver's log lines, to spdlog at their level.
void log_to_spdlog(skeleton::LogLevel level, const std::string& line);

}  // namespace mocap::daemon
