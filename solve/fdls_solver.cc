#include "solve/fdls_solver.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <optional>
#include <random>

#include "core/file_util.h"
#include "core/json_io.h"
#include "core/parallel_for.h"
#include "core/progress.h"

namespace facedyn::solve {
namespace {

// Rows are columns of two dense matrices (inputs F x N, targets K x N).
class DenseDataset final : public learn::MlpDataset {
 public:
  DenseDataset(const Eigen::MatrixXf* inputs, const Eigen::MatrixXf* targets)
      : inputs_(inputs), targets_(targets) {}
  int input_size() const override { return static_cast<int>(inputs_->rows()); }
  int output_size() const override { return static_cast<int>(targets_->rows()); }
  void Gather(const long* rows, long n, Eigen::MatrixXf* inputs,
              Eigen::MatrixXf* targets) const override {
    inputs->resize(inputs_->rows(), n);
    targets->resize(targets_->rows(), n);
    for (long i = 0; i < n; ++i) {
      inputs->col(i) = inputs_->col(rows[i]);
      targets->col(i) = targets_->col(rows[i]);
    }
  }

 private:
  const Eigen::MatrixXf* inputs_;
  const Eigen::MatrixXf* targets_;
};

Eigen::MatrixXd Rows(const Eigen::MatrixXd& matrix, const std::vector<int>& rows) {
  Eigen::MatrixXd out(rows.size(), matrix.cols());
  for (size_t r = 0; r < rows.size(); ++r)
    out.row(static_cast<Eigen::Index>(r)) = matrix.row(rows[r]);
  return out;
}

}  // namespace

Status FdlsTrainOptions::Check() const {
  if (num_threads < 0) return InvalidArgumentError(fmt::format("num_threads: {} < 0", num_threads));
  if (concurrent_networks < 1) {
    return InvalidArgumentError(fmt::format("concurrent_networks: {} < 1", concurrent_networks));
  }
  if (!(validation_fraction >= 0.0 && validation_fraction < 0.9)) {
    return InvalidArgumentError(
        fmt::format("validation_fraction: {} is not in [0, 0.9)", validation_fraction));
  }
  return Status::Ok();
}

Eigen::MatrixXf FdlsSolver::RegionInputs(const Puppet& puppet, const ResolvedRegion& region,
                                         const Eigen::MatrixXd& markers,
                                         const Eigen::MatrixXd* jaw) {
  const int n_markers = static_cast<int>(region.markers.size());
  const int features = FeatureSize(n_markers, region.spec.features);
  const int extra = jaw != nullptr ? static_cast<int>(jaw->rows()) : 0;
  Eigen::MatrixXf inputs(features + extra, markers.cols());
  Eigen::Matrix3Xd neutral(3, n_markers), frame(3, n_markers);
  for (int i = 0; i < n_markers; ++i)
    neutral.col(i) = puppet.neutral_markers_in_skull.col(region.markers[i]);
  for (Eigen::Index f = 0; f < markers.cols(); ++f) {
    for (int i = 0; i < n_markers; ++i)
      frame.col(i) = markers.col(f).segment<3>(3 * region.markers[i]);
    ComputeGraphFeatures(frame, neutral, region.spec.features, inputs.col(f).data());
    if (extra > 0) inputs.col(f).tail(extra) = jaw->col(f).cast<float>();
  }
  return inputs;
}

StatusOr<FdlsSolver::Network> FdlsSolver::TrainNetwork(
    const ResolvedRegion& region, const NetworkSpec& spec, const Eigen::MatrixXf& inputs,
    int jaw_inputs, const Eigen::MatrixXd& weights, const FdlsTrainOptions& options,
    RegionTrainSummary* summary) {
  const Eigen::MatrixXf targets = Rows(weights, region.channels).cast<float>();
  learn::MlpShape shape;
  shape.input_size = static_cast<int>(inputs.rows());
  shape.output_size = static_cast<int>(targets.rows());
  shape.hidden_units = spec.hidden_units;
  shape.residual = true;
  shape.dropout = spec.dropout;
  shape.hidden_layers = 1 + spec.residual_blocks;
  if (jaw_inputs > 0) {
    // The jaw joins in one more (residual) layer after the residual blocks (FDLS Fig. 4).
    shape.hidden_layers += 1;
    shape.extra_input_size = jaw_inputs;
    shape.extra_input_layer = shape.hidden_layers;
  }
  FACEDYN_RETURN_IF_ERROR(
      shape.Check().WithContext("network of region '" + region.spec.name + "'"));
  FACEDYN_ASSIGN_OR_RETURN(learn::Mlp mlp, learn::Mlp::Create(shape, options.seed));

  const long n = inputs.cols();
  std::vector<long> rows(n);
  std::iota(rows.begin(), rows.end(), 0L);
  std::mt19937_64 rng(options.seed + 17);
  std::shuffle(rows.begin(), rows.end(), rng);
  const long validation = static_cast<long>(std::floor(options.validation_fraction * n));
  std::vector<long> validation_rows(rows.begin(), rows.begin() + validation);
  std::vector<long> train_rows(rows.begin() + validation, rows.end());

  learn::MlpTrainOptions train;
  train.epochs = spec.epochs;
  train.batch_size = spec.batch_size;
  train.learning_rate = spec.learning_rate;
  train.weight_decay = spec.weight_decay;
  train.final_learning_rate_fraction = 0.1;  // a decayed rate settles the last epochs
  train.seed = options.seed;
  train.num_threads = options.num_threads;
  train.show_progress = options.show_progress;
  train.progress_label = "solve " + region.spec.name;
  DenseDataset data(&inputs, &targets);
  learn::MlpTrainSummary trained;
  FACEDYN_RETURN_IF_ERROR(
      learn::TrainMlp(data, train_rows, validation_rows, train, &mlp, &trained)
          .WithContext("training the network of region '" + region.spec.name + "'"));
  if (summary != nullptr) {
    summary->region = region.spec.name;
    summary->markers = static_cast<int>(region.markers.size());
    summary->inputs = shape.input_size;
    summary->outputs = shape.output_size;
    summary->train_rmse = trained.train_loss.empty() ? 0.0 : std::sqrt(trained.train_loss.back());
    summary->validation_rmse =
        trained.validation_loss.empty() ? 0.0 : std::sqrt(trained.validation_loss.back());
    summary->train_s = trained.train_s;
  }
  return Network{region, std::move(mlp)};
}

StatusOr<FdlsSolver> FdlsSolver::Train(const Puppet& puppet, const ResolvedConfig& config,
                                       const TrainingSet& data, const FdlsTrainOptions& options,
                                       std::vector<RegionTrainSummary>* summaries) {
  FACEDYN_RETURN_IF_ERROR(options.Check().WithContext("FDLS training options"));
  if (data.markers.rows() != 3 * puppet.marker_count() ||
      data.weights.rows() != puppet.channel_count() || data.markers.cols() != data.weights.cols() ||
      data.markers.cols() < 2) {
    return InvalidArgumentError(
        fmt::format("FDLS training: {} x {} markers and {} x {} weights for a puppet of {} markers "
                    "and {} channels",
                    data.markers.rows(), data.markers.cols(), data.weights.rows(),
                    data.weights.cols(), puppet.marker_count(), puppet.channel_count()));
  }
  FdlsSolver solver;
  solver.puppet_ = puppet;
  if (summaries != nullptr) summaries->clear();
  // Job 0 is the jaw's network, job 1 + r region r's. Eq. (4): the conditioned networks see the
  // ground-truth jaw while training, so no job waits for another.
  const Eigen::MatrixXd true_jaw = Rows(data.weights, config.jaw.channels);
  const int jobs = 1 + static_cast<int>(config.regions.size());
  std::vector<std::optional<Network>> networks(jobs);
  std::vector<RegionTrainSummary> job_summaries(jobs);
  const bool concurrent = ParallelThreadCount(options.concurrent_networks, jobs) > 1;
  FdlsTrainOptions job_options = options;
  job_options.show_progress = options.show_progress && !concurrent;
  Progress progress(
      "solve networks", jobs,
      options.show_progress && concurrent ? ProgressMode::kAuto : ProgressMode::kSilent);
  FACEDYN_RETURN_IF_ERROR(ParallelFor(jobs, options.concurrent_networks, [&](int job) -> Status {
    const ResolvedRegion& region = job == 0 ? config.jaw : config.regions[job - 1];
    const bool conditioned = job > 0 && region.spec.jaw_conditioned;
    const Eigen::MatrixXf inputs =
        RegionInputs(puppet, region, data.markers, conditioned ? &true_jaw : nullptr);
    FACEDYN_ASSIGN_OR_RETURN(
        networks[job], TrainNetwork(region, config.network, inputs,
                                    conditioned ? static_cast<int>(config.jaw.channels.size()) : 0,
                                    data.weights, job_options, &job_summaries[job]));
    progress.Advance();
    return Status::Ok();
  }));
  progress.Finish();
  solver.jaw_ = std::move(*networks[0]);
  for (int job = 1; job < jobs; ++job) solver.regions_.push_back(std::move(*networks[job]));
  if (summaries != nullptr) *summaries = std::move(job_summaries);
  return solver;
}

StatusOr<Eigen::MatrixXd> FdlsSolver::Solve(const Eigen::MatrixXd& markers_in_skull) const {
  if (markers_in_skull.rows() != 3 * puppet_.marker_count()) {
    return InvalidArgumentError(
        fmt::format("FDLS solve: {} marker rows, the solver's puppet has {} markers ({} rows)",
                    markers_in_skull.rows(), puppet_.marker_count(), 3 * puppet_.marker_count()));
  }
  if (!markers_in_skull.allFinite())
    return InvalidArgumentError("FDLS solve: a marker coordinate is not finite");
  const Eigen::Index n = markers_in_skull.cols();
  Eigen::MatrixXd weights = Eigen::MatrixXd::Zero(puppet_.channel_count(), n);
  auto clamp_into = [&](const ResolvedRegion& region, const Eigen::MatrixXf& predicted) {
    for (size_t k = 0; k < region.channels.size(); ++k) {
      const int c = region.channels[k];
      weights.row(c) = predicted.row(static_cast<Eigen::Index>(k))
                           .cast<double>()
                           .cwiseMax(puppet_.lower_bounds[c])
                           .cwiseMin(puppet_.upper_bounds[c]);
    }
  };
  clamp_into(jaw_.region,
             jaw_.mlp.Predict(RegionInputs(puppet_, jaw_.region, markers_in_skull, nullptr)));
  const Eigen::MatrixXd solved_jaw = Rows(weights, jaw_.region.channels);
  for (const Network& network : regions_) {
    const bool conditioned = network.region.spec.jaw_conditioned;
    clamp_into(network.region,
               network.mlp.Predict(RegionInputs(puppet_, network.region, markers_in_skull,
                                                conditioned ? &solved_jaw : nullptr)));
  }
  return weights;
}

StatusOr<Eigen::MatrixXd> FdlsSolver::Solve(
    const Eigen::MatrixXd& markers_in_skull,
    const Eigen::Array<bool, Eigen::Dynamic, Eigen::Dynamic>& present) const {
  if (present.rows() != puppet_.marker_count() || present.cols() != markers_in_skull.cols() ||
      markers_in_skull.rows() != 3 * puppet_.marker_count()) {
    return InvalidArgumentError(
        fmt::format("FDLS solve: {} x {} markers and {} x {} presence flags for {} markers",
                    markers_in_skull.rows(), markers_in_skull.cols(), present.rows(),
                    present.cols(), puppet_.marker_count()));
  }
  Eigen::MatrixXd filled = markers_in_skull;
  for (Eigen::Index f = 0; f < filled.cols(); ++f) {
    const Eigen::Array<bool, Eigen::Dynamic, 1> frame = present.col(f);
    if (frame.all()) continue;
    if (!frame.any())
      return InvalidArgumentError(fmt::format("FDLS solve: frame {} has no marker", f));
    FillMissingMarkers(puppet_, frame, filled.col(f));
  }
  return Solve(filled);
}

double FdlsSolver::ForwardMultiplyAdds() const {
  double total = jaw_.mlp.shape().ForwardMultiplyAdds();
  for (const Network& network : regions_) total += network.mlp.shape().ForwardMultiplyAdds();
  return total;
}

namespace {

constexpr int kSolverFormatVersion = 1;
constexpr const char* kNetworkKind = "fdls_region";

Json MatrixJson(const Eigen::MatrixXd& m) {
  return Json{{"rows", m.rows()},
              {"cols", m.cols()},
              {"data", std::vector<double>(m.data(), m.data() + m.size())}};
}

StatusOr<Eigen::MatrixXd> MatrixFromJson(const Json& j, const std::string& where) {
  if (!j.is_object() || !j.contains("rows") || !j.contains("cols") || !j.contains("data") ||
      !j["rows"].is_number_integer() || !j["cols"].is_number_integer() || !j["data"].is_array()) {
    return DataLossError(where + ": expected {rows, cols, data}");
  }
  const long rows = j["rows"].get<long>(), cols = j["cols"].get<long>();
  if (rows < 0 || cols < 0 || static_cast<long>(j["data"].size()) != rows * cols) {
    return DataLossError(
        fmt::format("{}: {} x {} with {} values", where, rows, cols, j["data"].size()));
  }
  Eigen::MatrixXd m(rows, cols);
  for (long i = 0; i < rows * cols; ++i) {
    if (!j["data"][static_cast<size_t>(i)].is_number())
      return DataLossError(where + ": a value is not a number");
    m.data()[i] = j["data"][static_cast<size_t>(i)].get<double>();
  }
  return m;
}

Json RegionJson(const ResolvedRegion& region) {
  return Json{{"name", region.spec.name},
              {"rig_regions", region.spec.rig_regions},
              {"channels", region.spec.channels},
              {"features", region.spec.features.ToString()},
              {"jaw_conditioned", region.spec.jaw_conditioned},
              {"marker_indices", region.markers},
              {"channel_indices", region.channels}};
}

}  // namespace

Status FdlsSolver::Save(const std::string& dir) const {
  FACEDYN_RETURN_IF_ERROR(MakeDirectories(dir));
  Json regions = Json::array();
  auto save_network = [&](const Network& network) -> Status {
    regions.push_back(RegionJson(network.region));
    return network.mlp.Save(dir + "/" + network.region.spec.name + ".pt", kNetworkKind,
                            Json{{"region", network.region.spec.name}});
  };
  FACEDYN_RETURN_IF_ERROR(save_network(jaw_));
  for (const Network& network : regions_) FACEDYN_RETURN_IF_ERROR(save_network(network));
  Json pairs = Json::array();
  for (const auto& [a, b] : puppet_.symmetric_pairs) pairs.push_back({a, b});
  const Json root = {{"format", "facedyn_fdls_solver"},
                     {"version", kSolverFormatVersion},
                     {"units", "mm"},
                     {"puppet",
                      {{"rig_name", puppet_.rig_name},
                       {"channel_names", puppet_.channel_names},
                       {"marker_names", puppet_.marker_names},
                       {"marker_vertices", puppet_.marker_vertices},
                       {"neutral_markers_in_skull", MatrixJson(puppet_.neutral_markers_in_skull)},
                       {"marker_basis_mm", MatrixJson(puppet_.marker_basis_mm)},
                       {"lower_bounds", MatrixJson(puppet_.lower_bounds)},
                       {"upper_bounds", MatrixJson(puppet_.upper_bounds)},
                       {"symmetric_pairs", pairs}}},
                     {"regions", regions}};  // the jaw first
  return WriteJsonFile(dir + "/solver.json", root);
}

StatusOr<FdlsSolver> FdlsSolver::Load(const std::string& dir) {
  const std::string path = dir + "/solver.json";
  FACEDYN_ASSIGN_OR_RETURN(const std::string text, ReadFileToString(path));
  const Json root = Json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (root.is_discarded() || !root.is_object()) return DataLossError(path + ": not a JSON object");
  if (root.value("format", "") != "facedyn_fdls_solver" ||
      root.value("version", 0) != kSolverFormatVersion) {
    return DataLossError(
        fmt::format("{}: not an FDLS solver of format version {}", path, kSolverFormatVersion));
  }
  if (!root.contains("puppet") || !root.contains("regions") || !root["regions"].is_array() ||
      root["regions"].empty()) {
    return DataLossError(path + ": missing 'puppet' or 'regions'");
  }
  FdlsSolver solver;
  Puppet& puppet = solver.puppet_;
  try {
    const Json& p = root["puppet"];
    puppet.rig_name = p.at("rig_name").get<std::string>();
    puppet.channel_names = p.at("channel_names").get<std::vector<std::string>>();
    puppet.marker_names = p.at("marker_names").get<std::vector<std::string>>();
    puppet.marker_vertices = p.at("marker_vertices").get<std::vector<int>>();
    for (const Json& pair : p.at("symmetric_pairs")) {
      puppet.symmetric_pairs.emplace_back(pair.at(0).get<int>(), pair.at(1).get<int>());
    }
  } catch (const Json::exception& e) {
    return DataLossError(path + ": puppet: " + e.what());
  }
  FACEDYN_ASSIGN_OR_RETURN(const Eigen::MatrixXd neutral,
                           MatrixFromJson(root["puppet"].value("neutral_markers_in_skull", Json()),
                                          path + ": neutral_markers_in_skull"));
  FACEDYN_ASSIGN_OR_RETURN(
      puppet.marker_basis_mm,
      MatrixFromJson(root["puppet"].value("marker_basis_mm", Json()), path + ": marker_basis_mm"));
  FACEDYN_ASSIGN_OR_RETURN(
      const Eigen::MatrixXd lower,
      MatrixFromJson(root["puppet"].value("lower_bounds", Json()), path + ": lower_bounds"));
  FACEDYN_ASSIGN_OR_RETURN(
      const Eigen::MatrixXd upper,
      MatrixFromJson(root["puppet"].value("upper_bounds", Json()), path + ": upper_bounds"));
  const int m_count = puppet.marker_count(), c_count = puppet.channel_count();
  if (neutral.rows() != 3 || neutral.cols() != m_count ||
      puppet.marker_basis_mm.rows() != 3 * m_count || puppet.marker_basis_mm.cols() != c_count ||
      lower.size() != c_count || upper.size() != c_count ||
      static_cast<int>(puppet.marker_vertices.size()) != m_count) {
    return DataLossError(fmt::format(
        "{}: puppet sizes disagree with its {} markers and {} channels", path, m_count, c_count));
  }
  puppet.neutral_markers_in_skull = neutral;
  puppet.lower_bounds = Eigen::Map<const Eigen::VectorXd>(lower.data(), c_count);
  puppet.upper_bounds = Eigen::Map<const Eigen::VectorXd>(upper.data(), c_count);

  const int jaw_size = [&] {
    try {
      return static_cast<int>(root["regions"][0].at("channel_indices").size());
    } catch (const Json::exception&) {
      return 0;
    }
  }();
  for (size_t r = 0; r < root["regions"].size(); ++r) {
    const Json& j = root["regions"][r];
    const std::string where = fmt::format("{}: regions[{}]", path, r);
    ResolvedRegion region;
    try {
      region.spec.name = j.at("name").get<std::string>();
      region.spec.rig_regions = j.at("rig_regions").get<std::vector<std::string>>();
      region.spec.channels = j.at("channels").get<std::vector<std::string>>();
      region.spec.jaw_conditioned = j.at("jaw_conditioned").get<bool>();
      region.markers = j.at("marker_indices").get<std::vector<int>>();
      region.channels = j.at("channel_indices").get<std::vector<int>>();
      StatusOr<FeatureSet> set = FeatureSet::Parse(j.at("features").get<std::string>());
      if (!set.ok()) return DataLossError(where + ": " + set.status().message());
      region.spec.features = set.value();
    } catch (const Json::exception& e) {
      return DataLossError(where + ": " + e.what());
    }
    for (int m : region.markers) {
      if (m < 0 || m >= m_count)
        return DataLossError(fmt::format("{}: marker index {} out of range", where, m));
    }
    for (int c : region.channels) {
      if (c < 0 || c >= c_count)
        return DataLossError(fmt::format("{}: channel index {} out of range", where, c));
    }
    if (region.markers.size() < 2 || region.channels.empty() ||
        (r == 0 && region.spec.jaw_conditioned)) {
      return DataLossError(
          where + ": needs 2 markers, a channel, and the first (jaw) region unconditioned");
    }
    Json config;
    FACEDYN_ASSIGN_OR_RETURN(learn::Mlp mlp, learn::Mlp::Load(dir + "/" + region.spec.name + ".pt",
                                                              kNetworkKind, &config));
    const int expected_inputs =
        FeatureSize(static_cast<int>(region.markers.size()), region.spec.features) +
        (region.spec.jaw_conditioned ? jaw_size : 0);
    if (mlp.shape().input_size != expected_inputs ||
        mlp.shape().output_size != static_cast<int>(region.channels.size()) ||
        mlp.shape().extra_input_size != (region.spec.jaw_conditioned ? jaw_size : 0)) {
      return DataLossError(
          fmt::format("{}/{}.pt: a {} -> {} network for a region of {} inputs and {} channels", dir,
                      region.spec.name, mlp.shape().input_size, mlp.shape().output_size,
                      expected_inputs, region.channels.size()));
    }
    Network network{std::move(region), std::move(mlp)};
    if (r == 0) {
      solver.jaw_ = std::move(network);
    } else {
      solver.regions_.push_back(std::move(network));
    }
  }
  return solver;
}

}  // namespace facedyn::solve
