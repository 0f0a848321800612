// take_export_budget.cpp — two limits over one map.
#include "serve/take_export_budget.hpp"

namespace mocap::serve {

namespace {

std::string mib(std::uint64_t bytes) {
    return std::to_string((bytes + (std::uint64_t{1} << 20) - 1) >> 20) + " MiB";
}

/// To a tenth of a MiB, rounded up: what an export that grows is refused at.
std::string mib_tenths(std::uint64_t bytes) {
    const std::uint64_t tenths = (bytes * 10 + (std::uint64_t{1} << 20) - 1) >> 20;
    return std::to_string(tenths / 10) + "." + std::to_string(tenths % 10) + " MiB";
}

}  // namespace

TakeExportBudget::Charge::~Charge() {
    std::lock_guard lock(books_->mutex);
    books_->total -= bytes_;
    const auto it = books_->by_address.find(address_);
    if (it == books_->by_address.end()) return;
    it->second -= bytes_;
    if (it->second == 0) books_->by_address.erase(it);
}

bool TakeExportBudget::fits(const std::string& address, std::uint64_t more, std::string* why) const {
    if (books_->total + more > total_limit_) {
        *why = "insufficient storage: take exports waiting for their readers hold " + mib(books_->total) + " of " +
               mib(total_limit_) + " and this one needs " + mib(more) + " more; retry when downloads finish";
        return false;
    }
    const auto it = books_->by_address.find(address);
    const std::uint64_t mine = it == books_->by_address.end() ? 0 : it->second;
    if (mine + more > address_limit_) {
        *why = "insufficient storage: exports for " + address + " hold " + mib(mine) + " of " + mib(address_limit_) +
               " per address and this one needs " + mib(more) + " more; finish those downloads first";
        return false;
    }
    return true;
}

std::shared_ptr<TakeExportBudget::Charge> TakeExportBudget::try_charge(const std::string& address, std::uint64_t bytes,
                                                                       std::string* why) {
    auto charge = std::make_shared<Charge>(books_, address);
    std::lock_guard lock(books_->mutex);
    if (!fits(address, bytes, why)) return nullptr;
    books_->total += bytes;
    books_->by_address[address] += bytes;
    charge->bytes_ = bytes;
    return charge;
}

bool TakeExportBudget::grow(Charge& charge, std::uint64_t held, std::uint64_t chunk, std::string* why) {
    std::lock_guard lock(books_->mutex);
    if (held <= charge.bytes_) return true;
    const std::uint64_t rounded = chunk == 0 ? held : (held + chunk - 1) / chunk * chunk;
    std::uint64_t& mine = books_->by_address[charge.address_];  // >= charge.bytes_
    const std::uint64_t others_total = books_->total - charge.bytes_;
    const std::uint64_t others_mine = mine - charge.bytes_;
    const auto fits_as = [&](std::uint64_t bytes) {
        return others_total + bytes <= total_limit_ && others_mine + bytes <= address_limit_;
    };
    const std::uint64_t to = fits_as(rounded) ? rounded : held;
    if (!fits_as(to)) {
        if (mine == 0) books_->by_address.erase(charge.address_);
        if (others_total + held > total_limit_) {
            *why = "insufficient storage: this export has grown to " + mib_tenths(held) +
                   " while the other take exports waiting for their readers hold " + mib_tenths(others_total) +
                   " of the " + mib_tenths(total_limit_) + " all may hold; retry when downloads finish";
        } else {
            *why = "insufficient storage: this export has grown to " + mib_tenths(held) + " while other exports for " +
                   charge.address_ + " hold " + mib_tenths(others_mine) + " of the " + mib_tenths(address_limit_) +
                   " one address may hold; " +
                   (others_mine > 0 ? "finish those downloads first"
                                    : "export the take on the host instead (mocapd --replay)");
        }
        return false;
    }
    books_->total = others_total + to;
    mine = others_mine + to;
    charge.bytes_ = to;
    return true;
}

bool TakeExportBudget::resize(Charge& charge, std::uint64_t bytes, std::string* why) {
    std::lock_guard lock(books_->mutex);
    if (bytes > charge.bytes_ && !fits(charge.address_, bytes - charge.bytes_, why)) return false;
    books_->total = books_->total - charge.bytes_ + bytes;
    std::uint64_t& mine = books_->by_address[charge.address_];
    mine = mine - charge.bytes_ + bytes;
    if (mine == 0) books_->by_address.erase(charge.address_);
    charge.bytes_ = bytes;
    return true;
}

std::uint64_t TakeExportBudget::held() const {
    std::lock_guard lock(books_->mutex);
    return books_->total;
}

std::uint64_t TakeExportBudget::held_by(const std::string& address) const {
    std::lock_guard lock(books_->mutex);
    const auto it = books_->by_address.find(address);
    return it == books_->by_address.end() ? 0 : it->second;
}

}  // namespace mocap::serve
