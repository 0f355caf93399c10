// `vksonar bench accuracy` (README "Accuracy and what it costs", issue 6): error vs time over the accuracy knobs,
// against the CPU backend in double precision at the highest settings, with every noise source off.
#ifdef VKSONAR_HAVE_BENCHMARK

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <string>
#include <system_error>
#include <vector>

#include <benchmark/benchmark.h>

#include "cli/bench_cmd.h"
#include "cli/bench_common.h"
#include "core/access.h"
#include "core/angles.h"
#include "core/plan.h"
#include "sonar_shared.h"

namespace fs = std::filesystem;

namespace vksonar::cli::bench {
namespace {

// The reference's side-lobe kernel: the whole fan (1000 beamwidths is past any fan; the plan stops the
// kernel at the last beam), so the reference truncates nothing.
const char* const kReferenceSidelobe = "1000";

constexpr const char* kUsage =
    "usage: vksonar bench accuracy [--frames N] [--scene FILE] [--sonar PRESET|FILE] [--set key=value ...]\n"
    "                              [--pose x,y,z,roll,pitch,yaw] [--out DIR] [--no-vulkan]\n"
    "\n"
    "Sweeps the accuracy knobs one at a time around the config (default: the bundled scene and preset):\n"
    "accuracy.pixels_per_beam 1,2,4,8; accuracy.rows_per_vfov 16,32,64,128; accuracy.max_slice 15,30,60,120;\n"
    "accuracy.range_kernel nearest,tent,footprint; accuracy.sidelobe_kernel_beamwidths 1,2,3,6;\n"
    "accuracy.far_sidelobe_cell 0 (no far side lobes), 1; accuracy.tier_pixel_ratio 2, 3;\n"
    "accuracy.normal_method sobel3,sobel5,geometric; accuracy.intermediates fp32,fp16; and the --quality presets\n"
    "fast, balanced, accurate.\n"
    "Reference: the CPU backend with cpu.precision=double, pixels_per_beam 8, rows_per_vfov 256, max_slice 15,\n"
    "range_kernel footprint, tier_pixel_ratio 1 (the finest tier views), the side-lobe kernel over the whole fan,\n"
    "and a second one with each row's own side-lobe kernel width (isolates the other knobs). Speckle, ambient\n"
    "noise and TVG are off everywhere.\n"
    "The reference is shown converged: each of its grid knobs is refined once more (pixels_per_beam 16,\n"
    "rows_per_vfov 512, the narrowest slices allowed) and the change is printed.\n"
    "Per setting: median ms per frame on Vulkan (N timed frames, default 10, after 2 warm-up frames) and on\n"
    "the CPU backend in float (3 frames), and for each the RMSE and the max |error| in dB over the cells\n"
    "whose reference level is above the noise floor NL - DI (a value below the floor counts as the floor).\n"
    "Writes DIR/bench_accuracy.csv and DIR/bench_accuracy.svg (RMSE vs ms, Pareto front); DIR defaults to '.'.\n";

struct Setting {
    std::string knob, value; // knob "default" for the unchanged config
};

struct Errors {
    double rmse_db = 0, max_db = 0;
    std::size_t cells = 0;
};

struct Row {
    Setting setting;
    double vulkan_ms = NAN, cpu_ms = NAN;
    Errors vulkan, cpu;                 // vs the reference
    Errors vulkan_matched, cpu_matched; // vs the reference with this row's side-lobe kernel width
    bool vulkan_done = false, cpu_done = false;
};

// dB error over the cells whose reference is above the noise floor; the tested value is floored there.
Errors compare(const std::vector<float>& reference, const std::vector<float>& tested, double source_linear,
               double floor_linear) {
    Errors e;
    double sum_sq = 0;
    for (std::size_t i = 0; i < reference.size() && i < tested.size(); ++i) {
        const double ref = source_linear * double(reference[i]);
        if (!(ref > floor_linear)) continue;
        const double value = std::max(source_linear * double(tested[i]), floor_linear);
        const double err = 10.0 * std::log10(value / ref);
        sum_sq += err * err;
        e.max_db = std::max(e.max_db, std::abs(err));
        ++e.cells;
    }
    e.rmse_db = e.cells ? std::sqrt(sum_sq / double(e.cells)) : 0.0;
    return e;
}

std::string csv_number(double v, int decimals) {
    return std::isfinite(v) ? fmt(v, decimals) : "";
}

std::string svg_escape(const std::string& text) {
    std::string out;
    for (char ch : text) {
        if (ch == '<')
            out += "&lt;";
        else if (ch == '>')
            out += "&gt;";
        else if (ch == '&')
            out += "&amp;";
        else
            out += ch;
    }
    return out;
}

// Indices of the points no other point beats in both time and error, sorted by time.
std::vector<std::size_t> pareto_front(const std::vector<double>& ms, const std::vector<double>& err) {
    std::vector<std::size_t> order(ms.size());
    for (std::size_t i = 0; i < order.size(); ++i)
        order[i] = i;
    std::sort(order.begin(), order.end(),
              [&](std::size_t a, std::size_t b) { return ms[a] != ms[b] ? ms[a] < ms[b] : err[a] < err[b]; });
    std::vector<std::size_t> front;
    double best = INFINITY;
    for (std::size_t i : order) {
        if (err[i] < best) {
            front.push_back(i);
            best = err[i];
        }
    }
    return front;
}

void write_svg(const fs::path& path, const std::vector<Row>& rows, bool vulkan, const std::string& title) {
    std::vector<double> ms, err;
    std::vector<std::string> labels;
    for (const auto& r : rows) {
        const double t = vulkan ? r.vulkan_ms : r.cpu_ms;
        const double e = vulkan ? r.vulkan.rmse_db : r.cpu.rmse_db;
        if (!std::isfinite(t) || !std::isfinite(e)) continue;
        ms.push_back(t);
        err.push_back(e);
        labels.push_back(r.setting.knob == "default" ? "default" : r.setting.knob + "=" + r.setting.value);
    }
    const double W = 900, H = 560, left = 70, right = 250, top = 50, bottom = 60;
    const double pw = W - left - right, ph = H - top - bottom;
    double x_max = 1e-9, y_max = 1e-9;
    for (double v : ms)
        x_max = std::max(x_max, v);
    for (double v : err)
        y_max = std::max(y_max, v);
    x_max *= 1.1;
    y_max *= 1.1;
    auto X = [&](double v) { return left + pw * v / x_max; };
    auto Y = [&](double v) { return top + ph * (1.0 - v / y_max); };

    std::ofstream out(path);
    if (!out) throw Failure("bench accuracy: cannot write " + path.string());
    char buf[512];
    out << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << W << "\" height=\"" << H
        << "\" font-family=\"sans-serif\" font-size=\"12\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
    out << "<text x=\"" << left << "\" y=\"25\" font-size=\"15\">" << svg_escape(title) << "</text>\n";
    std::snprintf(buf, sizeof buf,
                  "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"black\"/>\n"
                  "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"black\"/>\n",
                  left, top + ph, left + pw, top + ph, left, top, left, top + ph);
    out << buf;
    for (int i = 0; i <= 5; ++i) {
        const double xv = x_max * i / 5, yv = y_max * i / 5;
        std::snprintf(buf, sizeof buf,
                      "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\">%.3g</text>\n"
                      "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"end\">%.3g</text>\n"
                      "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"#ddd\"/>\n",
                      X(xv), top + ph + 18, xv, left - 6, Y(yv) + 4, yv, left, Y(yv), left + pw, Y(yv));
        out << buf;
    }
    std::snprintf(buf, sizeof buf,
                  "<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\">median ms per frame (%s)</text>\n"
                  "<text x=\"18\" y=\"%.1f\" transform=\"rotate(-90 18 %.1f)\" text-anchor=\"middle\">RMSE dB vs "
                  "reference (cells above the noise floor)</text>\n",
                  left + pw / 2, H - 20, vulkan ? "Vulkan" : "CPU float", top + ph / 2, top + ph / 2);
    out << buf;
    const std::vector<std::size_t> front = pareto_front(ms, err);
    std::string points;
    for (std::size_t i : front) {
        std::snprintf(buf, sizeof buf, "%.1f,%.1f ", X(ms[i]), Y(err[i]));
        points += buf;
    }
    out << "<polyline points=\"" << points << "\" fill=\"none\" stroke=\"#d62728\" stroke-width=\"2\"/>\n";
    for (std::size_t i = 0; i < ms.size(); ++i) {
        const bool on_front = std::find(front.begin(), front.end(), i) != front.end();
        std::snprintf(buf, sizeof buf,
                      "<circle cx=\"%.1f\" cy=\"%.1f\" r=\"4\" fill=\"%s\"/>\n"
                      "<text x=\"%.1f\" y=\"%.1f\" font-size=\"10\">%s</text>\n",
                      X(ms[i]), Y(err[i]), on_front ? "#d62728" : "#1f77b4", X(ms[i]) + 6, Y(err[i]) - 4,
                      svg_escape(labels[i]).c_str());
        out << buf;
    }
    std::snprintf(buf, sizeof buf,
                  "<text x=\"%.1f\" y=\"%.1f\" fill=\"#d62728\">red: Pareto front (no setting is both</text>\n"
                  "<text x=\"%.1f\" y=\"%.1f\" fill=\"#d62728\">faster and more accurate)</text>\n",
                  left + pw + 15, top + 10, left + pw + 15, top + 25);
    out << buf << "</svg>\n";
}

} // namespace

int run_bench_accuracy(const std::vector<std::string>& argv) {
    const Args args = parse_args(argv,
                                 {{"--frames", true, false},
                                  {"--scene", true, false},
                                  {"--sonar", true, false},
                                  {"--set", true, true},
                                  {"--pose", true, false},
                                  {"--out", true, false},
                                  {"--no-vulkan", false, false},
                                  {"--help", false, false}},
                                 "bench accuracy");
    if (args.has("--help")) {
        std::fputs(kUsage, stdout);
        return 0;
    }
    if (!args.positional.empty()) throw BadInput("bench accuracy: unexpected argument '" + args.positional[0] + "'");
    const std::uint32_t frames = frames_option(args, 10);
    constexpr std::uint32_t kWarmup = 2, kCpuFrames = 3;
    const fs::path out_dir = args.value("--out", ".");
    {
        std::error_code ec;
        fs::create_directories(out_dir, ec);
        if (!fs::is_directory(out_dir, ec)) throw BadInput("--out " + out_dir.string() + ": cannot create directory");
    }

    Setup setup = load_setup(args);
    std::vector<std::string> base_sets = args.values("--set");
    for (const char* quiet : {"effects.speckle=off", "effects.ambient_noise=off", "effects.tvg=off"})
        base_sets.emplace_back(quiet);
    const SonarConfig base = layered_config(setup, base_sets);
    const double source = std::pow(10.0, base.source_level_db / 10.0);
    // The broadside beam's floor NL - DI (the lowest of the beams'), "auto" resolved.
    const double floor_db = base.noise_terms().floor_db();
    const double floor = std::pow(10.0, floor_db / 10.0);

    std::unique_ptr<Context> vulkan_context;
    std::string vulkan_note;
    if (!args.has("--no-vulkan")) {
        try {
            vulkan_context = std::make_unique<Context>(make_context(Backend::vulkan));
        } catch (const Failure& e) {
            vulkan_note = e.what();
        }
    } else {
        vulkan_note = "--no-vulkan";
    }
    Context cpu_context = make_context(Backend::cpu);

    std::printf("vksonar bench accuracy: scene %s, sonar %s, Vulkan %s\n", setup.scene_path.c_str(),
                setup.sonar_name.c_str(),
                vulkan_context ? vulkan_context->device_description().c_str() : ("skipped: " + vulkan_note).c_str());

    // Reference.
    std::vector<std::string> ref_sets = base_sets;
    for (const char* s : {"accuracy.pixels_per_beam=8", "accuracy.rows_per_vfov=256", "accuracy.max_slice=15",
                          "accuracy.range_kernel=footprint", "accuracy.tier_pixel_ratio=1", "cpu.precision=double"})
        ref_sets.emplace_back(s);
    auto render_reference = [&](const std::string& sidelobe_width) {
        std::vector<std::string> sets = ref_sets;
        sets.push_back("accuracy.sidelobe_kernel_beamwidths=" + sidelobe_width);
        Renderer renderer = make_renderer(cpu_context, layered_config(setup, sets), setup.scene, Backend::cpu);
        Frame frame = renderer.make_frame();
        const double ms = timed_render(renderer, setup.pose, 0, frame);
        std::printf("reference (side-lobe kernel %s beamwidths): CPU double, %u x %u pixels, %s ms\n",
                    sidelobe_width.c_str(), frame.columns, frame.rows, fmt(ms, 1).c_str());
        return frame.clean;
    };
    const std::vector<float> reference = render_reference(kReferenceSidelobe);
    // An empty reference would print a table of zero errors that reads like a perfect score.
    if (compare(reference, reference, source, floor).cells == 0)
        throw BadInput("bench accuracy: no cell of the reference frame is above the noise floor (NL - DI = " +
                       fmt(floor_db, 1) + " dB): nothing is in view; check --scene, --pose and --sonar");
    // Converged? Refine each of the reference's grid knobs once more and print how far it moves.
    {
        // As many slices as the pixel grid may have over the azimuths it covers: the fan, or with the
        // line-array geometry the wider span of its edge cones (docs/pipeline.md, "Beam geometry").
        double covered_deg = base.hfov_deg;
        {
            std::vector<std::string> sets = ref_sets;
            sets.push_back("accuracy.sidelobe_kernel_beamwidths=" + std::string(kReferenceSidelobe));
            if (auto plan = make_plan(layered_config(setup, sets), scene_data(setup.scene)))
                covered_deg = plan->slice_width_rad * plan->slices * kRadToDeg;
        }
        const double narrowest_slice = std::ceil(covered_deg / shared::kMaxSlices * 1000.0) / 1000.0;
        const std::vector<std::pair<std::string, std::string>> finer = {
            {"accuracy.pixels_per_beam", "16"},
            {"accuracy.rows_per_vfov", "512"},
            {"accuracy.max_slice", fmt(std::max(narrowest_slice, 1.0), 3)}};
        for (const auto& [key, value] : finer) {
            std::vector<std::string> sets = ref_sets;
            sets.push_back("accuracy.sidelobe_kernel_beamwidths=" + std::string(kReferenceSidelobe));
            sets.push_back(key + "=" + value);
            Renderer renderer = make_renderer(cpu_context, layered_config(setup, sets), setup.scene, Backend::cpu);
            Frame frame = renderer.make_frame();
            const double ms = timed_render(renderer, setup.pose, 0, frame);
            const Errors moved = compare(frame.clean, reference, source, floor);
            std::printf("reference convergence: %s = %s (%u x %u pixels, %s ms) moves the reference by %s dB RMSE, "
                        "%s dB max\n",
                        key.c_str(), value.c_str(), frame.columns, frame.rows, fmt(ms, 1).c_str(),
                        fmt(moved.rmse_db, 3).c_str(), fmt(moved.max_db, 2).c_str());
        }
    }
    // Side-lobe truncation dominates the error of every row that keeps the default kernel width (cells
    // beyond the kernel's reach are empty instead of -40..-80 dB); a second reference with the row's own
    // width isolates the other knobs.
    std::map<std::string, std::vector<float>> matched;
    auto matched_reference = [&](const std::string& width) -> const std::vector<float>& {
        auto it = matched.find(width);
        if (it == matched.end()) it = matched.emplace(width, render_reference(width)).first;
        return it->second;
    };

    const std::vector<Setting> settings = {
        {"default", ""},
        {"pixels_per_beam", "1"},
        {"pixels_per_beam", "4"},
        {"pixels_per_beam", "8"},
        {"rows_per_vfov", "16"},
        {"rows_per_vfov", "32"},
        {"rows_per_vfov", "128"},
        {"max_slice", "15"},
        {"max_slice", "30"},
        {"max_slice", "120"},
        {"range_kernel", "nearest"},
        {"range_kernel", "tent"},
        {"sidelobe_kernel_beamwidths", "1"},
        {"sidelobe_kernel_beamwidths", "2"},
        {"sidelobe_kernel_beamwidths", "6"},
        {"far_sidelobe_cell", "0"},
        {"far_sidelobe_cell", "1"},
        {"tier_pixel_ratio", "2"},
        {"tier_pixel_ratio", "3"},
        {"normal_method", "sobel5"},
        {"normal_method", "geometric"},
        {"intermediates", "fp16"},
        {"quality", "fast"},
        {"quality", "balanced"},
        {"quality", "accurate"},
    };
    std::vector<Row> rows(settings.size());
    std::vector<const std::vector<float>*> row_matched(settings.size());
    for (std::size_t i = 0; i < settings.size(); ++i) {
        rows[i].setting = settings[i];
        std::vector<std::string> sets = base_sets;
        std::string width = fmt(base.sidelobe_kernel_beamwidths, 0);
        if (settings[i].knob == "quality") { // a whole --quality preset (src/config/quality.cpp)
            for (const std::string& s : quality_settings(settings[i].value)) {
                sets.push_back(s);
                const std::string key = "accuracy.sidelobe_kernel_beamwidths=";
                if (s.rfind(key, 0) == 0) width = s.substr(key.size());
            }
        } else if (settings[i].knob != "default") {
            sets.push_back("accuracy." + settings[i].knob + "=" + settings[i].value);
            if (settings[i].knob == "sidelobe_kernel_beamwidths") width = settings[i].value;
        }
        row_matched[i] = &matched_reference(width);
        const std::string label =
            settings[i].knob == "default" ? "default" : settings[i].knob + "=" + settings[i].value;
        if (vulkan_context) {
            benchmark::RegisterBenchmark(
                ("accuracy/vulkan/" + label).c_str(),
                [&, i, sets](benchmark::State& state) {
                    try {
                        Renderer renderer =
                            make_renderer(*vulkan_context, layered_config(setup, sets), setup.scene, Backend::vulkan);
                        Frame frame = renderer.make_frame();
                        std::uint64_t index = 0;
                        for (std::uint32_t w = 0; w < kWarmup; ++w)
                            timed_render(renderer, setup.pose, index++, frame);
                        std::vector<double> ms;
                        ms.reserve(frames);
                        for (auto _ : state) {
                            ms.push_back(timed_render(renderer, setup.pose, index++, frame));
                            state.SetIterationTime(ms.back() * 1e-3);
                        }
                        rows[i].vulkan_ms = median(ms);
                        rows[i].vulkan = compare(reference, frame.clean, source, floor);
                        rows[i].vulkan_matched = compare(*row_matched[i], frame.clean, source, floor);
                        rows[i].vulkan_done = true;
                        state.counters["rmse_db"] = rows[i].vulkan.rmse_db;
                        state.counters["max_db"] = rows[i].vulkan.max_db;
                    } catch (const std::exception& e) {
                        state.SkipWithError(e.what());
                        record_failure(setup, e.what());
                    }
                })
                ->UseManualTime()
                ->Iterations(frames)
                ->Unit(benchmark::kMillisecond);
        }
        benchmark::RegisterBenchmark(("accuracy/cpu_float/" + label).c_str(),
                                     [&, i, sets](benchmark::State& state) {
                                         try {
                                             std::vector<std::string> cpu_sets = sets;
                                             cpu_sets.emplace_back("cpu.precision=float");
                                             Renderer renderer =
                                                 make_renderer(cpu_context, layered_config(setup, cpu_sets),
                                                               setup.scene, Backend::cpu);
                                             Frame frame = renderer.make_frame();
                                             std::vector<double> ms;
                                             std::uint64_t index = 0;
                                             for (auto _ : state) {
                                                 ms.push_back(timed_render(renderer, setup.pose, index++, frame));
                                                 state.SetIterationTime(ms.back() * 1e-3);
                                             }
                                             rows[i].cpu_ms = median(ms);
                                             rows[i].cpu = compare(reference, frame.clean, source, floor);
                                             rows[i].cpu_matched = compare(*row_matched[i], frame.clean, source, floor);
                                             rows[i].cpu_done = true;
                                             state.counters["rmse_db"] = rows[i].cpu.rmse_db;
                                             state.counters["max_db"] = rows[i].cpu.max_db;
                                         } catch (const std::exception& e) {
                                             state.SkipWithError(e.what());
                                             record_failure(setup, e.what());
                                         }
                                     })
            ->UseManualTime()
            ->Iterations(kCpuFrames)
            ->Unit(benchmark::kMillisecond);
    }
    run_registered_benchmarks(setup);

    std::printf("\n## vksonar bench accuracy (reference: CPU double at the highest settings; noise off; errors "
                "over cells above NL - DI = %s dB)\n\n",
                fmt(floor_db, 1).c_str());
    std::printf("Errors in dB, RMSE / max |error|: vs the reference (side-lobe kernel %s beamwidths), then vs a "
                "reference with the row's own side-lobe kernel width (isolates the other knobs).\n\n",
                kReferenceSidelobe);
    std::printf("| knob | value | Vulkan ms | Vulkan RMSE / max | same width: RMSE / max | CPU float ms | CPU float "
                "RMSE / max | same width: RMSE / max | cells |\n|---|---|---:|---:|---:|---:|---:|---:|---:|\n");
    const fs::path csv_path = out_dir / "bench_accuracy.csv";
    std::ofstream csv(csv_path);
    if (!csv) throw Failure("bench accuracy: cannot write " + csv_path.string());
    csv << "knob,value,vulkan_median_ms,vulkan_rmse_db,vulkan_max_db,vulkan_rmse_db_same_sidelobe,"
           "vulkan_max_db_same_sidelobe,cpu_float_median_ms,cpu_float_rmse_db,cpu_float_max_db,"
           "cpu_float_rmse_db_same_sidelobe,cpu_float_max_db_same_sidelobe,cells\n";
    for (const auto& r : rows) {
        const std::string value = r.setting.knob == "default" ? "-" : r.setting.value;
        auto pair = [](bool done, const Errors& e) {
            return done ? fmt(e.rmse_db, 3) + " / " + fmt(e.max_db, 1) : std::string("n/a");
        };
        std::printf("| %s | %s | %s | %s | %s | %s | %s | %s | %zu |\n", r.setting.knob.c_str(), value.c_str(),
                    r.vulkan_done ? fmt(r.vulkan_ms, 2).c_str() : "n/a", pair(r.vulkan_done, r.vulkan).c_str(),
                    pair(r.vulkan_done, r.vulkan_matched).c_str(), r.cpu_done ? fmt(r.cpu_ms, 2).c_str() : "n/a",
                    pair(r.cpu_done, r.cpu).c_str(), pair(r.cpu_done, r.cpu_matched).c_str(),
                    r.cpu_done ? r.cpu.cells : r.vulkan.cells);
        auto csv_errors = [](bool done, const Errors& e) {
            return done ? csv_number(e.rmse_db, 4) + "," + csv_number(e.max_db, 4) : std::string(",");
        };
        csv << r.setting.knob << "," << (r.setting.knob == "default" ? "" : r.setting.value) << ","
            << (r.vulkan_done ? csv_number(r.vulkan_ms, 3) : "") << "," << csv_errors(r.vulkan_done, r.vulkan) << ","
            << csv_errors(r.vulkan_done, r.vulkan_matched) << "," << (r.cpu_done ? csv_number(r.cpu_ms, 3) : "") << ","
            << csv_errors(r.cpu_done, r.cpu) << "," << csv_errors(r.cpu_done, r.cpu_matched) << ","
            << (r.cpu_done ? r.cpu.cells : r.vulkan.cells) << "\n";
    }
    csv.close();
    const fs::path svg_path = out_dir / "bench_accuracy.svg";
    const bool plot_vulkan = vulkan_context != nullptr;
    write_svg(svg_path, rows, plot_vulkan,
              std::string("vksonar bench accuracy: error vs time (") + (plot_vulkan ? "Vulkan" : "CPU float") +
                  "), scene " + fs::path(setup.scene_path).filename().string());
    std::printf("\nwrote %s and %s\n", csv_path.string().c_str(), svg_path.string().c_str());
    std::printf("(timings vary +-30-50%% between runs on lavapipe; compare settings from the same run)\n");
    return 0;
}

} // namespace vksonar::cli::bench

#endif // VKSONAR_HAVE_BENCHMARK
