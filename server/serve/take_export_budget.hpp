// take_export_budget.hpp — the memory that finished take exports (BVH/CSV in memfds, waiting
// for their reader) may hold, in total and per peer address (docs/reliability.md, "Export
// memory").
//
// An export is charged as it grows: one chunk when it is asked for (before it is queued, so a
// client whose address already holds its share cannot queue work), then, while the export
// is written, whatever its memfd holds (grow(), in chunks), and its real size once written.
// A request or a growth that does not fit is refused (HTTP 507) with the reason the budget
// gives. So a take is refused for what its export really holds, never for its raw file's
// size. A Charge gives its bytes back when it is destroyed: when the download has been sent,
// or its connection closed. Exports live in memory rather than on record_dir's disk so that
// slow downloads can never take the disk a running take records to.
//
// Threads: any; one mutex, held for a map lookup. A Charge may outlive the budget.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>

namespace mocap::serve {

class TakeExportBudget {
    struct Books {
        std::mutex mutex;
        std::uint64_t total = 0;                          // mutex
        std::map<std::string, std::uint64_t> by_address;  // mutex: addresses that hold > 0
    };

public:
    /// Bytes held by one export; given back on destruction.
    class Charge {
    public:
        Charge(std::shared_ptr<Books> books, std::string address)
            : books_(std::move(books)), address_(std::move(address)) {}
        ~Charge();
        Charge(const Charge&) = delete;
        Charge& operator=(const Charge&) = delete;
        [[nodiscard]] std::uint64_t bytes() const { return bytes_; }

    private:
        friend class TakeExportBudget;
        std::shared_ptr<Books> books_;
        std::string address_;
        std::uint64_t bytes_ = 0;  // books_->mutex
    };

    TakeExportBudget(std::uint64_t total_bytes, std::uint64_t per_address_bytes)
        : total_limit_(total_bytes), address_limit_(per_address_bytes) {}

    /// A charge of `bytes` for `address`; nullptr + *why when it would exceed a limit.
    std::shared_ptr<Charge> try_charge(const std::string& address, std::uint64_t bytes, std::string* why);
    /// Makes `charge` cover `held` bytes (what its export holds so far): nothing when it does
    /// already, else it grows to `held` rounded up to a multiple of `chunk`, or to `held`
    /// exactly when only that fits. False + *why, the charge unchanged, when even `held`
    /// does not fit.
    bool grow(Charge& charge, std::uint64_t held, std::uint64_t chunk, std::string* why);
    /// Sets `charge` to `bytes` (the export's real size). False + *why, the charge unchanged,
    /// when growing it would exceed a limit.
    bool resize(Charge& charge, std::uint64_t bytes, std::string* why);

    [[nodiscard]] std::uint64_t held() const;
    [[nodiscard]] std::uint64_t held_by(const std::string& address) const;

private:
    bool fits(const std::string& address, std::uint64_t more, std::string* why) const;  // mutex held

    std::uint64_t total_limit_;
    std::uint64_t address_limit_;
    std::shared_ptr<Books> books_ = std::make_shared<Books>();
};

}  // namespace mocap::serve
