// mocap-sim: benchmark recordings and simulated sink nodes. One subcommand per file pair
// (csv_command, ...); main only dispatches.
#include <CLI/CLI.hpp>

#include "core/guarded_main.hpp"
#include "sim/csv_command.hpp"
#include "sim/field_command.hpp"
#include "sim/stream_command.hpp"

static int run(int argc, char** argv) {
    CLI::App app{"mocap-sim: simulated IMU data for mocapd and its benchmarks"};
    app.require_subcommand(1);

    mocap::sim::CsvCommandOptions csv;
    CLI::App* csv_cmd = mocap::sim::add_csv_command(app, csv);
    mocap::sim::StreamCommandOptions stream;
    CLI::App* stream_cmd = mocap::sim::add_stream_command(app, stream);
    mocap::sim::FieldCommandOptions field;
    CLI::App* field_cmd = mocap::sim::add_field_command(app, field);

    CLI11_PARSE(app, argc, argv);
    if (csv_cmd->parsed()) return mocap::sim::run_csv_command(csv);
    if (stream_cmd->parsed()) return mocap::sim::run_stream_command(stream);
    if (field_cmd->parsed()) return mocap::sim::run_field_command(field);
    return 2;
}

int main(int argc, char** argv) {
    return mocap::guarded_main("mocap-sim", [&] { return run(argc, argv); });
}
