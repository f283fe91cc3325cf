// The removal network F of Zoss et al. 2020, section 5.2: one MLP shared by every skin sample,
//
//   dx_i(t) = F(B(t), X_i(t))                                                    (Eq. 7 input)
//   y_i(t)  = x_i(t) - T(t) F(B(t), X_i(t))                                      (Eq. 7)
//
// input = [B(t) flattened; X_i(t) flattened] (features.h layout), two hidden layers of 128 with
// ReLU, output dx_i (3, skull frame, mm). Inputs and outputs are normalised per dimension with
// the mean and standard deviation of the training set; both live in the model, so callers
// always pass and receive raw features and millimetres.
//
// RemovalModel hides LibTorch behind a pointer to an implementation, so including this header
// costs no LibTorch parse (only removal_model.cc includes <torch/torch.h>).
//
// File format (RemovalModel::Save / Load): one LibTorch archive (zip, torch::serialize), holding
// the parameters and normalisation buffers under their module names plus one string entry
// "facedyn_removal_config", a JSON object with format_version, fps, window_s, window_frames,
// landmarks (names and positions in the skull frame, mm), sample_count, samples_hash (FNV-1a
// 64 of the skin samples' vertex indices and barycentric weights, hex), hidden_units and the
// sizes. Loading checks the sizes against the stored tensors; applying a model to a take
// checks fps and the rig's landmarks and samples against the stored configuration.
//
// Determinism: training on CPU is reproducible for a seed and a LibTorch thread count
// (TrainOptions::num_threads; LibTorch's intra-op parallelism splits work statically, so the
// same count gives the same summation order). torch::set_num_threads is process-wide.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/face_rig.h"
#include "core/status.h"
#include "core/take.h"
#include "dynamics/features.h"

namespace facedyn::dynamics {

// FNV-1a 64 over every sample's three vertex indices (int32) and weights (float64), in order.
uint64_t HashSurfacePoints(const std::vector<SurfacePoint>& points);

// What a removal model's input means; saved with it.
struct RemovalConfig {
  FeatureConfig features;
  std::vector<SkullLandmark> landmarks;  // B(t) landmarks, skull frame, mm
  int sample_count = 0;
  uint64_t samples_hash = 0;
  int hidden_units = 128;

  // Config for a rig's landmarks and samples at `fps` (other feature settings default).
  static RemovalConfig ForRig(const FaceRig& rig, double fps);

  int input_size() const {
    return features.SkullDescriptorSize(static_cast<int>(landmarks.size())) +
           features.SkinDescriptorSize();
  }
  // features valid, at least one landmark, sample_count >= 1, hidden_units >= 1.
  Status Check() const;
};

class RemovalModel {
 public:
  RemovalModel();
  ~RemovalModel();
  RemovalModel(RemovalModel&&) noexcept;
  RemovalModel& operator=(RemovalModel&&) noexcept;

  // A freshly initialised network (torch::manual_seed(seed) first; identity normalisation).
  static StatusOr<RemovalModel> Create(const RemovalConfig& config, uint64_t seed);
  static StatusOr<RemovalModel> Load(const std::string& path);
  Status Save(const std::string& path) const;

  const RemovalConfig& config() const;
  bool valid() const { return impl_ != nullptr; }

  // FailedPrecondition naming what differs: "fps", "skull_landmarks", "skin_samples".
  Status CheckCompatible(const Take& take, const FaceRig& rig) const;

  // Raw features (input_size x N, columns = [B; X_i]) -> dx (3 x N, skull frame, mm).
  // Precondition: features.rows() == config().input_size().
  Eigen::MatrixXf Predict(const Eigen::MatrixXf& features) const;

  // Per-dimension normalisation (sizes: input_size, input_size, 3, 3; std > 0).
  void SetNormalisation(const Eigen::VectorXf& input_mean, const Eigen::VectorXf& input_std,
                        const Eigen::VectorXf& output_mean, const Eigen::VectorXf& output_std);

  // Every parameter and buffer, flattened in module order (for tests and fingerprints).
  std::vector<float> FlatParameters() const;

  struct Impl;

 private:
  friend struct RemovalTrainer;
  std::unique_ptr<Impl> impl_;
};

// One training take: the dynamic take and the rig that defines its landmarks and samples.
struct TrainingTake {
  const Take* take = nullptr;
  const FaceRig* rig = nullptr;
};

struct TrainOptions {
  int epochs = 250;             // the paper converges after 250
  int batch_size = 10000;       // the paper's batch
  double learning_rate = 1e-3;  // Adam
  double validation_fraction = 0.1;  // fraction of (take, frame) pairs held out, all samples
  uint64_t seed = 1;
  int num_threads = 0;  // LibTorch intra-op threads; 0 keeps the current setting
  int hidden_units = 128;
  double window_s = 0.08;  // feature and moving-average half-window
  // Targets from the take's exact "quasistatic" channel when it has one (simulated takes);
  // otherwise, and by default, the moving average of Eq. (5)-(6) as in the paper.
  bool use_exact_targets = false;
  bool show_progress = true;
  // epochs >= 1, batch_size >= 1, learning_rate > 0, validation_fraction in [0, 0.9],
  // num_threads >= 0, hidden_units >= 1, window_s in (0, 1]. The message names the field.
  Status Check() const;
};

struct TrainSummary {
  long training_samples = 0;    // (take, frame, sample) rows used for training
  long validation_samples = 0;
  std::vector<double> train_loss;       // per epoch, mean L2 on normalised outputs
  std::vector<double> validation_loss;  // per epoch (empty when no validation rows)
  double train_s = 0.0;                 // wall time of the optimisation
  double samples_per_s = 0.0;           // training rows through forward + backward per second
};

// Trains F on the takes (which must share fps, landmarks and samples). Frames within the
// feature window of either end of a take are left out (their windows read replicated frames).
// Errors: no takes, mismatched takes, a requested exact target channel that is missing.
StatusOr<RemovalModel> TrainRemoval(const std::vector<TrainingTake>& takes,
                                    const TrainOptions& options, TrainSummary* summary = nullptr);

// First propagation of sample offsets to every vertex: each vertex takes a normalised Gaussian
// blend of its k nearest samples on the neutral (skull frame), sigma = the mean distance
// between neighbouring samples, weights relative to the nearest sample so none underflows.
// A prefactorised Laplacian deformation (or the ALM of Wu et al. 2016 the paper uses) is the
// better later step: this blend ignores the surface and can leak across the lips.
struct SamplePropagation {
  int k = 0;
  std::vector<int> sample_index;  // V * k
  std::vector<float> weight;      // V * k, each vertex's k weights sum to 1
};
SamplePropagation BuildSamplePropagation(const FaceRig& rig, int k = 8);

struct RemovalSummary {
  double predict_s = 0.0;    // features + network
  double propagate_s = 0.0;  // offsets to vertices
  double frames_per_s = 0.0;
};

// Eq. (7) on a whole take, batched over samples and frames, then propagated: the result is a
// copy of `take` whose positions are the quasistatic estimate x - T(t) dx(t) for every vertex
// and whose only channel is "dynamic_offset" (the propagated dx, skull frame, mm);
// info.source "dynamics remove". Errors: an incompatible take or rig (CheckCompatible).
StatusOr<Take> RemoveDynamics(const RemovalModel& model, const Take& take, const FaceRig& rig,
                              RemovalSummary* summary = nullptr);

}  // namespace facedyn::dynamics
