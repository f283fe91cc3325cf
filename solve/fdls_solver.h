// The FDLS learned solver (sections 4.3-4.4): a jaw network from the jaw-region markers, then one
// network per region on that region's graph features, the region networks that the tables mark
// jaw_conditioned taking the jaw weights as extra nodes in a hidden layer after the residual
// blocks (section 4.4.1, Fig. 4; supplementary section 8).
//
// Training follows Eq. (4): the conditioned networks are trained with the ground-truth jaw
// weights of each tuple; solving feeds them the jaw network's output. Each network is a
// learn::Mlp: a first hidden layer, `residual_blocks` residual layers, one more residual layer
// that also takes the jaw (conditioned networks only), a linear output; inputs and outputs
// normalised per dimension. The solved weights are clamped to the puppet's bounds.
//
// Why one class owns every network: solving is a fixed pipeline over them (jaw, then the rest)
// and the features of each are computed from the same frame, so the batch of frames is turned
// into features once per region and passed through each network in one Predict call.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "core/status.h"
#include "learn/mlp.h"
#include "solve/puppet.h"
#include "solve/solve_config.h"
#include "solve/training_data.h"

namespace facedyn::solve {

struct FdlsTrainOptions {
  uint64_t seed = 1;
  int num_threads = 0;               // LibTorch threads while training (0: leave as is)
  // Networks trained at once, each on its own thread (the jaw's and the regions' are independent
  // while training: Eq. 4 conditions the regions on the true jaw). The networks are bitwise
  // those trained one at a time (learn/mlp.h, Determinism). LibTorch runs these small networks
  // on one core whatever num_threads says, so 2 on a 2-core machine halves the training time.
  // With more than 1, show_progress counts finished networks instead of each one's epochs.
  int concurrent_networks = 1;
  double validation_fraction = 0.1;  // tuples held out of each network's optimisation
  bool show_progress = false;
  Status Check() const;
};

struct RegionTrainSummary {
  std::string region;
  int markers = 0;
  int inputs = 0;                // features (+ jaw channels when conditioned)
  int outputs = 0;               // channels
  double train_rmse = 0.0;       // weight RMSE on its training tuples, last epoch
  double validation_rmse = 0.0;  // on the held-out tuples (0 without any)
  double train_s = 0.0;
};

class FdlsSolver {
 public:
  // Trains the jaw network and the region networks (options.concurrent_networks at once) on `data`
  // (3M x N markers of the puppet, C x N weights). Errors: options, a data set that does not match
  // the puppet, a network that fails to train.
  static StatusOr<FdlsSolver> Train(const Puppet& puppet, const ResolvedConfig& config,
                                    const TrainingSet& data, const FdlsTrainOptions& options,
                                    std::vector<RegionTrainSummary>* summaries);

  // Stacked markers (3M x N, skull frame, mm, every marker present: see FillMissingMarkers) ->
  // weights (C x N) within the puppet's bounds. Error: wrong number of rows.
  StatusOr<Eigen::MatrixXd> Solve(const Eigen::MatrixXd& markers_in_skull) const;
  // The same with missing markers (present: M x N, false where missing), each refilled from its
  // nearest present neighbours (FillMissingMarkers, as the training dropout refills them).
  // Errors: sizes, a frame without any marker.
  StatusOr<Eigen::MatrixXd> Solve(
      const Eigen::MatrixXd& markers_in_skull,
      const Eigen::Array<bool, Eigen::Dynamic, Eigen::Dynamic>& present) const;

  // A folder: solver.json (the puppet: channel and marker names, neutral markers, B, bounds;
  // the regions: markers, channels, features, conditioning) and one LibTorch archive per
  // network (<region>.pt, learn::Mlp's format, kind "fdls_region"). Written file by file; a
  // failure part-way leaves a folder that Load rejects (solver.json is written last).
  Status Save(const std::string& dir) const;
  // Errors name the folder and the file: missing, not JSON, sizes that disagree, a network
  // whose shape does not match its region.
  static StatusOr<FdlsSolver> Load(const std::string& dir);

  const Puppet& puppet() const { return puppet_; }
  // Channel indices of the jaw network's outputs.
  const std::vector<int>& jaw_channels() const { return jaw_.region.channels; }
  // Multiply-adds of one frame through every network (for throughput figures).
  double ForwardMultiplyAdds() const;

 private:
  struct Network {
    ResolvedRegion region;
    learn::Mlp mlp;
  };
  // Features (F x N) of the region's markers for every frame, jaw rows appended when given.
  static Eigen::MatrixXf RegionInputs(const Puppet& puppet, const ResolvedRegion& region,
                                      const Eigen::MatrixXd& markers, const Eigen::MatrixXd* jaw);
  static StatusOr<Network> TrainNetwork(const ResolvedRegion& region, const NetworkSpec& spec,
                                        const Eigen::MatrixXf& inputs, int jaw_inputs,
                                        const Eigen::MatrixXd& weights,
                                        const FdlsTrainOptions& options,
                                        RegionTrainSummary* summary);

  Puppet puppet_;
  Network jaw_;
  std::vector<Network> regions_;
};

}  // namespace facedyn::solve
