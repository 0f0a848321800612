// mocap-filter: runs one orientation filter over a benchmark recording (docs/design.md, "Command-line contracts").
//
//   mocap-filter --filter NAME [--param k=v]... [--frame enu|ned] --in IN.csv --out OUT.csv
//                [--eval] [--skip-seconds S] [--trace TRACE.csv | --offline]
//   mocap-filter --chain CHAIN.toml --out-dir DIR [--filter NAME] [--param k=v]... [--no-mag] [--offline]
//                [--heading magnetometer|joints|auto] [--chain-param k=v]... [--eval]
//   mocap-filter --list        prints every filter name with its parameter keys and defaults
//
// --chain runs every segment of a chain recording (chain_file.hpp) through the filter (default
// "mocap") and the chain stage (chain_run.hpp) and writes DIR/<segment>.csv and DIR/joints.csv;
// --eval then prints per-segment and per-joint errors as one JSON object. --no-mag ignores
// every magnetometer column; --offline re-solves the take non-causally (chain_run.hpp). --chain-param sets a
// chain-stage parameter (fusion::ChainParams, the keys listed by --help) for studies.
//
// Exit codes: 0 success, 1 bad input file / output not writable, 2 bad command line or
// filter parameters. --eval prints one JSON object (evaluation.hpp) on stdout. --trace writes
// the filter's disturbance flags and bias estimate per sample (filter_run.hpp) and changes
// nothing else. --offline re-solves the whole recording non-causally with the filter
// (filter/offline_smoother.hpp: forward and backward passes, blended) instead of running it
// causally; --eval and --frame apply to it as to a causal run.
#include <CLI/CLI.hpp>

#include <fstream>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include "core/guarded_main.hpp"
#include "filter/filter_factory.hpp"
#include "filter_tool/chain_param.hpp"
#include "filter_tool/chain_run.hpp"
#include "filter_tool/evaluation.hpp"
#include "filter_tool/filter_run.hpp"
#include "filter_tool/recording_csv.hpp"

namespace {

int fail(int code, const std::string& message) {
    std::cerr << "mocap-filter: " << message << '\n';
    return code;
}

/// key=value pairs in order; false + *bad (the offending text) for one without '='.
bool split_params(const std::vector<std::string>& args, mocap::filter::FilterParamList& out, std::string* bad) {
    for (const std::string& kv : args) {
        const auto eq = kv.find('=');
        if (eq == std::string::npos || eq == 0) {
            *bad = kv;
            return false;
        }
        out.emplace_back(kv.substr(0, eq), kv.substr(eq + 1));
    }
    return true;
}

int run_chain_mode(const std::string& chain_path, const std::string& out_dir,
                   const mocap::tools::ChainRunOptions& options, bool eval) {
    std::string error;
    const auto chain = mocap::tools::load_chain(chain_path, &error);
    if (!chain) return fail(1, error);
    const auto run = options.offline ? mocap::tools::run_chain_offline(*chain, options, &error)
                                     : mocap::tools::run_chain(*chain, options, &error);
    if (!run) return fail(2, error);
    if (!mocap::tools::write_chain_outputs(out_dir, *chain, *run, &error)) return fail(1, error);
    if (eval) std::cout << mocap::tools::chain_eval_json(*chain, *run, options) << std::endl;
    return 0;
}

}  // namespace

static int run(int argc, char** argv) {
    CLI::App app{"mocap-filter: run one orientation filter over a recording, optionally evaluate it"};
    std::string filter_name;
    std::vector<std::string> param_args;
    std::string frame_name = "enu";
    std::string in_path;
    std::string out_path;
    std::string trace_path;
    bool eval = false;
    bool offline = false;
    double skip_seconds = 0.0;
    bool list = false;
    std::string chain_path, out_dir, heading = "auto";
    bool no_mag = false;
    std::vector<std::string> chain_param_args;
    app.add_option("--chain", chain_path, "Chain recording (CHAIN.toml: segments, their CSVs, the joints)");
    app.add_option("--out-dir", out_dir, "With --chain: where <segment>.csv and joints.csv go");
    app.add_flag("--no-mag", no_mag, "With --chain: ignore every magnetometer column");
    app.add_option("--heading", heading, "With --chain: heading source, magnetometer | joints | auto")
        ->check(CLI::IsMember({"magnetometer", "joints", "auto"}))
        ->capture_default_str();
    app.add_option(
           "--chain-param", chain_param_args,
           "With --chain: chain-stage parameter key=value (repeatable; " + mocap::tools::chain_param_keys() + ")")
        ->allow_extra_args(false)
        ->take_all();
    app.add_flag("--list", list, "Print every filter name with its parameters (key=default) and exit");
    app.add_option("--filter", filter_name, "Filter name (see --list)");
    app.add_option("--param", param_args, "Filter parameter key=value (repeatable)")
        ->allow_extra_args(false)
        ->take_all();
    app.add_option("--frame", frame_name, "Earth frame of the reference and of the output: enu | ned")
        ->check(CLI::IsMember({"enu", "ned"}))
        ->capture_default_str();
    app.add_option("--in", in_path, "Input CSV: t,gx,gy,gz,ax,ay,az,mx,my,mz[,qw,qx,qy,qz][,movement]");
    app.add_option("--out", out_path, "Output CSV: t,qw,qx,qy,qz");
    app.add_option("--trace", trace_path,
                   "Per-sample CSV of the filter's disturbance flags and gyro bias estimate (why an estimate went "
                   "wrong)");
    app.add_flag("--offline", offline,
                 "Re-solve the whole recording non-causally (forward and backward passes of the filter, blended)");
    app.add_flag("--eval", eval, "Print the error metrics against the reference as one JSON object");
    app.add_option("--skip-seconds", skip_seconds, "Do not evaluate the first S seconds (convergence)")
        ->check(CLI::NonNegativeNumber)
        ->capture_default_str();
    CLI11_PARSE(app, argc, argv);

    if (list) {
        for (const std::string_view name : mocap::filter::filter_names()) {
            std::cout << name;
            for (const mocap::filter::FilterKey& k : mocap::filter::filter_keys(name)) {
                std::cout << ' ' << k.key << '=' << k.default_value;
            }
            std::cout << '\n';
        }
        return 0;
    }
    // key=value pairs in order; a key given twice takes its last value (filter_factory.hpp).
    mocap::filter::FilterParamList params;
    std::string bad;
    if (!split_params(param_args, params, &bad)) return fail(2, "--param '" + bad + "' is not key=value");
    if (!chain_path.empty()) {
        if (out_dir.empty()) return fail(2, "--chain needs --out-dir");
        if (!in_path.empty() || !out_path.empty() || !trace_path.empty()) {
            return fail(2, "--chain cannot go with --in, --out or --trace");
        }
        mocap::tools::ChainRunOptions options;
        if (!filter_name.empty()) options.filter = filter_name;
        options.params = params;
        options.no_mag = no_mag;
        options.offline = offline;
        options.skip_seconds = skip_seconds;
        options.chain.mode = *mocap::fusion::parse_heading_mode(heading);
        mocap::filter::FilterParamList chain_params;
        if (!split_params(chain_param_args, chain_params, &bad)) {
            return fail(2, "--chain-param '" + bad + "' is not key=value");
        }
        if (const std::string e = mocap::tools::apply_chain_params(chain_params, options.chain); !e.empty()) {
            return fail(2, e);
        }
        return run_chain_mode(chain_path, out_dir, options, eval);
    }
    if (filter_name.empty() || in_path.empty() || out_path.empty()) {
        return fail(2, "--filter, --in and --out are required (see --help)");
    }
    if (offline && !trace_path.empty()) return fail(2, "--trace describes a causal run; it cannot go with --offline");

    std::string error;
    std::unique_ptr<mocap::filter::OrientationFilter> filter = mocap::filter::make_filter(filter_name, params, &error);
    if (!filter) return fail(2, error);

    std::ifstream in(in_path, std::ios::binary);
    if (!in) return fail(1, "cannot open '" + in_path + "'");
    mocap::tools::Recording recording;
    if (const auto err = mocap::tools::read_recording_csv(in, recording)) {
        return fail(1, in_path + ": " + err->to_string());
    }
    if (eval && !recording.has_reference) {
        return fail(1, in_path + ": --eval needs the reference columns qw,qx,qy,qz");
    }

    mocap::tools::RunOptions options;
    options.frame = *mocap::tools::parse_earth_frame(frame_name);
    options.skip_seconds = skip_seconds;
    options.trace = !trace_path.empty();
    const mocap::tools::RunOutput run =
        offline ? mocap::tools::run_offline(*filter, mocap::filter::OfflineSmoother(), recording, options)
                : mocap::tools::run_filter(*filter, recording, options);

    std::ofstream out(out_path, std::ios::binary | std::ios::trunc);
    if (!out || !mocap::tools::write_orientation_csv(out, run.estimates) || !out.flush()) {
        return fail(1, "cannot write '" + out_path + "'");
    }
    if (options.trace) {
        std::ofstream trace(trace_path, std::ios::binary | std::ios::trunc);
        if (!trace || !mocap::tools::write_trace_csv(trace, run.trace) || !trace.flush()) {
            return fail(1, "cannot write '" + trace_path + "'");
        }
    }
    if (eval) {
        const mocap::tools::EvalResult result = mocap::tools::evaluate(run.compared);
        if (result.samples == 0) std::cerr << "mocap-filter: warning: no sample was evaluated\n";
        std::cout << mocap::tools::eval_json(result, filter->name()) << std::endl;
    }
    return 0;
}

int main(int argc, char** argv) {
    return mocap::guarded_main("mocap-filter", [&] { return run(argc, argv); });
}
