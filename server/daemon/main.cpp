// mocapd — entry point: command line, config, logging, then the Daemon.
#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>

#include <cstdio>
#include <iostream>

#include "daemon/config.hpp"
#include "daemon/daemon.hpp"

int main(int argc, char** argv) {
    using namespace mocap::daemon;
    CLI::App app{"mocapd — networked inertial motion capture daemon"};
    std::string config_path;
    std::string check_path;
    bool print_default = false;
    app.add_option("--config", config_path, "TOML config (default: the embedded config/mocapd.toml)");
    app.add_option("--check-config", check_path, "validate FILE and exit (0 = valid)");
    app.add_flag("--print-default-config", print_default, "print the embedded default config and exit");
    CLI11_PARSE(app, argc, argv);

    if (print_default) {
        std::cout << embedded_default_config();
        return 0;
    }
    std::string error;
    if (!check_path.empty()) {
        auto c = load_config_file(check_path, &error);
        if (c && !body_model_from_config(*c, &error)) c.reset();
        if (!c) {
            std::cerr << "mocapd: invalid config: " << error << "\n";
            return 1;
        }
        std::cout << check_path << ": valid\n";
        return 0;
    }
    auto config = config_path.empty() ? parse_config(embedded_default_config(), "<embedded mocapd.toml>", &error)
                                      : load_config_file(config_path, &error);
    if (!config) {
        std::cerr << "mocapd: " << error << "\n";
        return 1;
    }
    spdlog::set_level(spdlog::level::from_str(config->log_level));
    Daemon daemon(*config, config_path);
    if (!daemon.start(&error)) {
        spdlog::critical("cannot start: {}", error);
        return 1;
    }
    daemon.run();
    return 0;
}
