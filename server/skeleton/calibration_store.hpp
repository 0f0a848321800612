// calibration_store.hpp — where a subject's calibration is kept between runs, injected
// into the PoseSolver so the skeleton layer does no file I/O (the daemon provides the
// file-backed store, daemon/calibration_files.hpp; tests keep calibrations in memory).
//
// Both calls run on the thread that drives the solver (load at set-up, save after a
// successful calibration: rare and small), so a store needs no locking of its own.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "skeleton/body_model.hpp"
#include "skeleton/calibration.hpp"

namespace mocap::skeleton {

/// What a store holds for one subject.
struct StoredCalibration {
    std::optional<Calibration> calibration;  ///< nullopt: nothing stored, or unusable (error)
    std::string where;                       ///< where it is kept, for the log (e.g. a path)
    std::string error;                       ///< why a stored calibration is unusable
};

class CalibrationStore {
public:
    virtual ~CalibrationStore() = default;
    /// The subject's saved calibration, checked against the model.
    virtual StoredCalibration load(const BodyModel& model, std::uint32_t subject_id) = 0;
    /// Replaces the subject's saved calibration. Returns "" or what went wrong, for the log.
    virtual std::string save(const BodyModel& model, std::uint32_t subject_id, const Calibration& calibration) = 0;
};

}  // namespace mocap::skeleton
