#include "solve/fdls_solver.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <random>

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
  for (size_t r = 0; r < rows.size(); ++r) out.row(static_cast<Eigen::Index>(r)) = matrix.row(rows[r]);
  return out;
}

}  // namespace

Status FdlsTrainOptions::Check() const {
  if (num_threads < 0) return InvalidArgumentError(fmt::format("num_threads: {} < 0", num_threads));
  if (!(validation_fraction >= 0.0 && validation_fraction < 0.9)) {
    return InvalidArgumentError(fmt::format("validation_fraction: {} is not in [0, 0.9)", validation_fraction));
  }
  return Status::Ok();
}

Eigen::MatrixXf FdlsSolver::RegionInputs(const Puppet& puppet, const ResolvedRegion& region,
                                         const Eigen::MatrixXd& markers, const Eigen::MatrixXd* jaw) {
  const int n_markers = static_cast<int>(region.markers.size());
  const int features = FeatureSize(n_markers, region.spec.features);
  const int extra = jaw != nullptr ? static_cast<int>(jaw->rows()) : 0;
  Eigen::MatrixXf inputs(features + extra, markers.cols());
  Eigen::Matrix3Xd neutral(3, n_markers), frame(3, n_markers);
  for (int i = 0; i < n_markers; ++i) neutral.col(i) = puppet.neutral_markers_in_skull.col(region.markers[i]);
  for (Eigen::Index f = 0; f < markers.cols(); ++f) {
    for (int i = 0; i < n_markers; ++i) frame.col(i) = markers.col(f).segment<3>(3 * region.markers[i]);
    ComputeGraphFeatures(frame, neutral, region.spec.features, inputs.col(f).data());
    if (extra > 0) inputs.col(f).tail(extra) = jaw->col(f).cast<float>();
  }
  return inputs;
}

StatusOr<FdlsSolver::Network> FdlsSolver::TrainNetwork(
    const Puppet& puppet, const ResolvedRegion& region, const NetworkSpec& spec,
    const Eigen::MatrixXf& inputs, int jaw_inputs, const Eigen::MatrixXd& weights,
    const FdlsTrainOptions& options, RegionTrainSummary* summary) {
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
  FACEDYN_RETURN_IF_ERROR(shape.Check().WithContext("network of region '" + region.spec.name + "'"));
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
  FACEDYN_RETURN_IF_ERROR(learn::TrainMlp(data, train_rows, validation_rows, train, &mlp, &trained)
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
  (void)puppet;
  return Network{region, std::move(mlp)};
}

StatusOr<FdlsSolver> FdlsSolver::Train(const Puppet& puppet, const ResolvedConfig& config,
                                       const TrainingSet& data, const FdlsTrainOptions& options,
                                       std::vector<RegionTrainSummary>* summaries) {
  FACEDYN_RETURN_IF_ERROR(options.Check().WithContext("FDLS training options"));
  if (data.markers.rows() != 3 * puppet.marker_count() || data.weights.rows() != puppet.channel_count() ||
      data.markers.cols() != data.weights.cols() || data.markers.cols() < 2) {
    return InvalidArgumentError(fmt::format(
        "FDLS training: {} x {} markers and {} x {} weights for a puppet of {} markers and {} channels",
        data.markers.rows(), data.markers.cols(), data.weights.rows(), data.weights.cols(),
        puppet.marker_count(), puppet.channel_count()));
  }
  FdlsSolver solver;
  solver.puppet_ = puppet;
  if (summaries != nullptr) summaries->clear();
  RegionTrainSummary summary;
  {
    const Eigen::MatrixXf inputs = RegionInputs(puppet, config.jaw, data.markers, nullptr);
    FACEDYN_ASSIGN_OR_RETURN(solver.jaw_, TrainNetwork(puppet, config.jaw, config.network, inputs, 0,
                                                       data.weights, options, &summary));
    if (summaries != nullptr) summaries->push_back(summary);
  }
  // Eq. (4): the conditioned networks see the ground-truth jaw while training.
  const Eigen::MatrixXd true_jaw = Rows(data.weights, config.jaw.channels);
  for (const ResolvedRegion& region : config.regions) {
    const bool conditioned = region.spec.jaw_conditioned;
    const Eigen::MatrixXf inputs =
        RegionInputs(puppet, region, data.markers, conditioned ? &true_jaw : nullptr);
    FACEDYN_ASSIGN_OR_RETURN(
        Network network,
        TrainNetwork(puppet, region, config.network, inputs,
                     conditioned ? static_cast<int>(config.jaw.channels.size()) : 0, data.weights,
                     options, &summary));
    solver.regions_.push_back(std::move(network));
    if (summaries != nullptr) summaries->push_back(summary);
  }
  return solver;
}

StatusOr<Eigen::MatrixXd> FdlsSolver::Solve(const Eigen::MatrixXd& markers_in_skull) const {
  if (markers_in_skull.rows() != 3 * puppet_.marker_count()) {
    return InvalidArgumentError(fmt::format("FDLS solve: {} marker rows, the solver's puppet has {} markers ({} rows)",
                                            markers_in_skull.rows(), puppet_.marker_count(),
                                            3 * puppet_.marker_count()));
  }
  if (!markers_in_skull.allFinite()) return InvalidArgumentError("FDLS solve: a marker coordinate is not finite");
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
  clamp_into(jaw_.region, jaw_.mlp.Predict(RegionInputs(puppet_, jaw_.region, markers_in_skull, nullptr)));
  const Eigen::MatrixXd solved_jaw = Rows(weights, jaw_.region.channels);
  for (const Network& network : regions_) {
    const bool conditioned = network.region.spec.jaw_conditioned;
    clamp_into(network.region,
               network.mlp.Predict(RegionInputs(puppet_, network.region, markers_in_skull,
                                                conditioned ? &solved_jaw : nullptr)));
  }
  return weights;
}

double FdlsSolver::ForwardMultiplyAdds() const {
  double total = jaw_.mlp.shape().ForwardMultiplyAdds();
  for (const Network& network : regions_) total += network.mlp.shape().ForwardMultiplyAdds();
  return total;
}

}  // namespace facedyn::solve
