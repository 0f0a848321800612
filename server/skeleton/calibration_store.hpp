// calibration_store.hpp — where a subject's calibration is kept between runs, injected
// into the PoseSolver so the skeleton layer does no file I/O (the daemon provides the
// file-backed store, daemon/calibration_files.hpp; tests keep calibrations in memory).
//
// load, save and serving run on the thread that drives the solver (load at set-up, save
// after a successful calibration, serving at a subject's first frame: rare and small), so a
// store that only keeps files needs no locking of its own. A store shared by several hosts
// (cluster/calibration_bucket.hpp) also hands the solver calibrations made elsewhere, from a
// thread of its own, through the OfferFn it is bound to; such a store must not block the
// solver's thread in save or serving (they queue work for its thread).
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>

#include "core/metrics_registry.hpp"
#include "skeleton/body_model.hpp"
#include "skeleton/calibration.hpp"

namespace mocap::skeleton {

/// What a store holds for one subject.
struct StoredCalibration {
    std::optional<Calibration> calibration;  ///< nullopt: nothing stored, or unusable (error)
    std::string where;                       ///< where it is kept, for the log (e.g. a path)
    std::string error;                       ///< why a stored calibration is unusable
};

/// A calibration made elsewhere, for the solver to apply (PoseSolver::offer_calibration).
/// saves_seen: how many of this host's own calibrations of the subject the store had been
/// given (save) when it decided to offer this one; a later local calibration wins.
using OfferFn = std::function<void(std::uint32_t subject_id, const Calibration& calibration, const std::string& where,
                                   std::uint64_t saves_seen)>;

class CalibrationStore {
public:
    virtual ~CalibrationStore() = default;
    /// Set-up, once, by the solver that owns the store: the model every stored calibration is
    /// checked against, and where calibrations made elsewhere go. A store that has no
    /// "elsewhere" ignores it.
    /// `offer` is a sink parameter, by value: a store that keeps it moves it into a member
    /// (the default ignores it, which the check below takes for a needless copy).
    // NOLINTNEXTLINE(performance-unnecessary-value-param)
    virtual void bind(const BodyModel& /*model*/, OfferFn /*offer*/) {}
    /// The solver's thread, at a subject's first frame: a shared store looks for the newest
    /// calibration of the subject (and offers it when it is newer than the one in use).
    virtual void serving(std::uint32_t /*subject_id*/) {}
    /// Set-up: the store's own counters, if it has any.
    virtual void register_metrics(MetricsRegistry& /*registry*/) const {}
    /// The subject's saved calibration, checked against the model.
    virtual StoredCalibration load(const BodyModel& model, std::uint32_t subject_id) = 0;
    /// Replaces the subject's saved calibration. Returns "" or what went wrong, for the log.
    virtual std::string save(const BodyModel& model, std::uint32_t subject_id, const Calibration& calibration) = 0;
};

}  // namespace mocap::skeleton
