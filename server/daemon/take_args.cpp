#include "daemon/take_args.hpp"

#include <filesystem>

#include "serve/take_store.hpp"

namespace mocap::daemon {

namespace fs = std::filesystem;

std::optional<std::vector<std::string>> expand_take_args(const std::vector<std::string>& args,
                                                         const std::string& record_dir, std::string* error) {
    std::vector<std::string> files;
    for (const std::string& arg : args) {
        std::error_code ec;
        if (fs::is_regular_file(arg, ec)) {
            files.push_back(arg);
            continue;
        }
        std::optional<serve::TakeEntry> take;
        std::string where;
        if (fs::is_directory(arg, ec)) {
            fs::path dir = fs::path(arg).lexically_normal();
            if (!dir.has_filename()) dir = dir.parent_path();  // "takes/walk1/"
            where = dir.string();
            take = serve::TakeStore(dir.parent_path().string()).find(dir.filename().string());
        } else if (serve::valid_take_name(arg)) {
            const std::string takes = record_dir + "/takes";
            where = (fs::path(takes) / arg).string();
            take = serve::TakeStore(takes).find(arg);
        }
        if (!take) {
            *error = arg + ": neither a raw recording file nor a take" +
                     (where.empty() ? std::string() : " (no readable take.json in " + where + ")");
            return std::nullopt;
        }
        if (take->raw_files.empty()) {
            *error = arg + ": take '" + take->meta.name + "' has no raw file";
            return std::nullopt;
        }
        files.insert(files.end(), take->raw_files.begin(), take->raw_files.end());
    }
    return files;
}

}  // namespace mocap::daemon
