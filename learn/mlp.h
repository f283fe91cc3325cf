// A normalised multilayer perceptron and its trainer: the shared engine of every network
// facedyn trains (learn/): today the removal network F and the synthesis network H of Zoss et
// al. 2020 (sections 5.2 and 6.2, dynamics/), which differ only in their features, sizes and
// batch sizes; next the rig solver's region networks (solve/, FDLS).
//
//   y = MLP((x - input_mean) / input_std) * output_std + output_mean
//
// MLP: `hidden_layers` fully connected layers of `hidden_units` with ReLU, then a linear output
// layer; optionally plus a linear map of the normalised inputs (MlpShape::linear_skip). Three
// options from Weta's FDLS (section 4.4: its region networks are residual MLPs trained with
// dropout, and the mouth's take the solved jaw as an extra input part-way in): residual hidden
// layers, dropout while training, and inputs that join a later hidden layer. The
// per-dimension normalisation lives in the model as buffers, so callers always pass raw features
// and receive raw outputs (mm).
//
// Mlp hides LibTorch behind a pointer to an implementation, so including this header costs no
// LibTorch parse (only mlp.cc includes <torch/torch.h>).
//
// File format (Save / Load): one LibTorch archive (zip, torch::serialize) holding the parameters
// and normalisation buffers under their module names ("fc1".."fcN", "input_mean", ...), plus two
// string entries: "facedyn_model_kind" (e.g. "removal", "synthesis") and "facedyn_model_config",
// a JSON object with the MLP's shape under "mlp" and the caller's own configuration beside it.
// Loading checks the kind, the shape against every stored tensor, and returns the JSON.
// Attachments: named float matrices stored beside the network (e.g. a model's learned
// propagation), each as a flat tensor "facedyn_attachment_<name>" in Eigen's column-major order,
// its rows and columns listed in the config under "attachments".
//
// Determinism (dropout included: it draws from the trainer's own generator, seeded from
// MlpTrainOptions::seed): training on CPU is reproducible for a seed and a LibTorch thread count
// (MlpTrainOptions::num_threads; LibTorch's intra-op parallelism splits work statically, so the
// same count gives the same summation order). torch::set_num_threads is process-wide.
// Independent networks may be created and trained on different threads at once with the same
// results as one after the other: Create seeds and draws the initial weights under a lock, and
// training draws only from its own generators.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "core/json_io.h"
#include "core/status.h"

namespace facedyn::learn {

struct MlpShape {
  int input_size = 0;
  int hidden_units = 128;
  int hidden_layers = 2;
  int output_size = 3;
  // Adds a linear map of the normalised inputs to the output ("skip", no bias, zero at
  // initialisation): y = MLP(x) + W x. For F it lowered the error at a platform frequency above
  // every training frequency (removal_model.h RemovalTrainOptions::linear_skip has the
  // figures). False is the paper's network.
  bool linear_skip = false;
  // Hidden layers 2..hidden_layers as residual blocks, h_k = relu(fc_k(in_k)) + h_{k-1}, where
  // in_k is h_{k-1} (plus the extra inputs at extra_input_layer). False: the plain stack.
  bool residual = false;
  // Probability of zeroing each hidden activation while training (inverted dropout: the kept
  // ones are scaled by 1/(1-p)); never when predicting or validating. 0: none.
  double dropout = 0.0;
  // The last `extra_input_size` inputs skip the first layers: hidden layer `extra_input_layer`
  // (2..hidden_layers, counting the first hidden layer as 1) takes them concatenated to the
  // previous layer's activations, and the first layer sees only the others. The normalisation
  // covers them like every input. 0: none (and extra_input_layer must be 0).
  int extra_input_size = 0;
  int extra_input_layer = 0;
  // Sizes >= 1, dropout in [0, 1), extra inputs fewer than the inputs and their layer in range.
  // The message names the field.
  Status Check() const;
  // Multiply-adds of one forward pass of one row (for throughput figures).
  double ForwardMultiplyAdds() const;
};

// Named matrices saved and loaded with a network (see the file format above).
using MlpAttachments = std::map<std::string, Eigen::MatrixXf>;

class Mlp {
 public:
  Mlp();
  ~Mlp();
  Mlp(Mlp&&) noexcept;
  Mlp& operator=(Mlp&&) noexcept;

  // A freshly initialised network (torch::manual_seed(seed) first; identity normalisation).
  static StatusOr<Mlp> Create(const MlpShape& shape, uint64_t seed);
  // `config` must be a JSON object; its "mlp" and "attachments" keys are written by Save.
  Status Save(const std::string& path, const std::string& kind, Json config,
              const MlpAttachments& attachments = {}) const;
  // DataLoss for a truncated or foreign file, a kind other than `expected_kind`, or tensors that
  // disagree with the stored shape (attachments included); the message starts with the path.
  // `attachments` may be null (they are then not read).
  static StatusOr<Mlp> Load(const std::string& path, const std::string& expected_kind, Json* config,
                            MlpAttachments* attachments = nullptr);

  bool valid() const { return impl_ != nullptr; }
  const MlpShape& shape() const;
  // A deep copy (weights, normalisation), to train on while keeping the original.
  Mlp Clone() const;

  // Raw inputs (input_size x N, column per row) -> raw outputs (output_size x N).
  // Precondition: inputs.rows() == shape().input_size.
  Eigen::MatrixXf Predict(const Eigen::MatrixXf& inputs) const;

  // Per-dimension normalisation (sizes input, input, output, output; std > 0).
  void SetNormalisation(const Eigen::VectorXf& input_mean, const Eigen::VectorXf& input_std,
                        const Eigen::VectorXf& output_mean, const Eigen::VectorXf& output_std);

  // Every parameter and buffer, flattened in module order (for tests and fingerprints).
  std::vector<float> FlatParameters() const;

  struct Impl;

 private:
  friend struct MlpTrainer;
  std::unique_ptr<Impl> impl_;
};

// Where training rows come from. Rows are gathered a batch at a time (one virtual call per
// batch), so a dataset may keep its features compactly (e.g. B(t) once per frame for all
// samples) and assemble rows on demand.
class MlpDataset {
 public:
  virtual ~MlpDataset() = default;
  virtual int input_size() const = 0;
  virtual int output_size() const = 0;
  // Raw inputs (input_size x n) and targets (output_size x n) of rows[0..n).
  virtual void Gather(const long* rows, long n, Eigen::MatrixXf* inputs,
                      Eigen::MatrixXf* targets) const = 0;
};

struct MlpTrainOptions {
  int epochs = 250;
  int batch_size = 10000;
  // > 0: train for exactly this many Adam steps instead of `epochs` whole epochs; the epochs are
  // then ceil(steps / batches per epoch) and the last one stops after the budget's last step.
  // For comparisons that must differ only in their data (paper Fig. 5: every bar the same
  // number of steps whatever its training rows).
  long optimizer_steps = 0;
  double learning_rate = 1e-3;  // Adam, at the first epoch
  // Exponential decay of the learning rate to this fraction of it at the last epoch
  // (lr_e = lr * fraction^(e / (epochs - 1))); 1 keeps it constant, as the paper states.
  double final_learning_rate_fraction = 1.0;
  // Decoupled weight decay (AdamW, Loshchilov & Hutter 2019): every step shrinks each weight
  // and bias by learning_rate * weight_decay of itself, apart from the gradient step. A
  // regulariser for generalising beyond the training conditions (e.g. F at an unseen platform
  // frequency); 0, the default, trains with plain Adam as the paper does.
  double weight_decay = 0.0;
  // Standard deviation of Gaussian noise added to the normalised inputs of every training batch
  // (not to validation rows): smooths the fitted function around the training features. 0, the
  // default, adds none.
  double input_noise_std = 0.0;
  // The loss: false is the mean squared error of the per-dimension normalised outputs, where a
  // quiet output (a forehead sample of H, F's least varying axis) weighs as much as a cheek;
  // true, the default, weights dimension d by std_d^2 / mean(std^2), so the loss is the squared
  // error in the outputs' own units (mm, Zoss et al. 2020's L2) up to that one constant, which
  // keeps the step size of the normalised loss.
  bool loss_in_output_units = true;
  uint64_t seed = 1;    // initialisation, shuffling and input noise
  int num_threads = 0;  // LibTorch intra-op threads; 0 keeps the current setting
  bool show_progress = true;
  std::string progress_label = "train";
  // epochs >= 1, batch_size >= 1, optimizer_steps >= 0, learning_rate > 0, final_learning_rate_fraction in (0, 1],
  // weight_decay >= 0, input_noise_std >= 0, num_threads >= 0. Names the field.
  Status Check() const;
};

struct MlpTrainSummary {
  long training_rows = 0;
  long validation_rows = 0;
  // Per epoch, the mean squared error per output dimension: in the outputs' units squared (mm^2)
  // with loss_in_output_units, else of the normalised outputs (a last epoch cut short by an
  // optimizer_steps budget: over the rows it reached).
  std::vector<double> train_loss;
  std::vector<double> validation_loss;  // per epoch (empty without validation rows)
  long optimizer_steps = 0;             // Adam steps taken (mini-batches over all epochs)
  int epochs = 0;                       // epochs run (the last may be partial, see above)
  double train_s = 0.0;                 // wall time of the optimisation
  double rows_per_s = 0.0;              // training rows through forward + backward per second
};

// Fits the normalisation to the training rows (mean and standard deviation per dimension;
// constant dimensions get std 1), then minimises the squared error of the outputs (weighted per
// dimension, see loss_in_output_units) with Adam over shuffled mini-batches. `model` must have the dataset's sizes.
// Errors: no training rows, a size mismatch.
Status TrainMlp(const MlpDataset& data, const std::vector<long>& train_rows,
                const std::vector<long>& validation_rows, const MlpTrainOptions& options,
                Mlp* model, MlpTrainSummary* summary);

// --- Two networks trained together with a consistency term ---
//
// Zoss et al. 2020 (section 8.1) propose chaining the removal network F and the synthesis
// network H: F removes a performance's dynamics, H resynthesises them from F's quasistatic and
// the head motion, and the reconstruction of the captured take is a loss that needs no target.
// The reconstruction x - F + H equals x exactly when H's offsets equal F's, so the cycle's loss
// is the disagreement of the two networks' offsets. TrainMlpPair minimises
//
//   L = L_first + L_second + pair_weight * L_pair
//
// L_first, L_second: each network's own supervised loss (its TrainMlp loss, in output units);
// L_pair: the mean squared difference, in the first network's output units, between the first
// network's outputs over a group of rows and the second network's one output for that group
// (e.g. F over the S samples of a frame, 3 outputs each, and H's 3S outputs for the frame).
// Both networks must be trained already: their normalisations are kept, and this fine-tunes.

// The consistency rows: each row is a group of `group_size()` rows of the first network and
// one row of the second, whose output_size is group_size() * first output_size (the first
// network's outputs of group member i are the second's outputs [i * m, (i + 1) * m)).
class MlpPairDataset {
 public:
  virtual ~MlpPairDataset() = default;
  virtual int first_input_size() const = 0;
  virtual int second_input_size() const = 0;
  virtual int group_size() const = 0;
  // Raw inputs of rows[0..n): the first network's (first_input_size x n * group_size, column
  // r * group_size + i for member i of row r) and the second's (second_input_size x n).
  virtual void Gather(const long* rows, long n, Eigen::MatrixXf* first_inputs,
                      Eigen::MatrixXf* second_inputs) const = 0;
};

struct MlpPairTrainOptions {
  // Adam steps; each takes one batch of each supervised set and one of consistency rows.
  long steps = 1000;
  // Progress and the losses are reported every this many steps (an "epoch" of the report).
  long steps_per_report = 100;
  double learning_rate = 1e-4;  // fine-tuning: below the 1e-3 the networks were trained at
  long first_batch = 10000;     // supervised rows of the first network per step
  long second_batch = 50;       // supervised rows of the second network per step
  long pair_batch = 16;         // consistency rows (groups) per step
  double pair_weight = 1.0;
  // Whether the consistency term also trains the second network; false keeps its parameters
  // fixed (it is then a teacher of the first on the consistency rows).
  bool pair_trains_second = true;
  uint64_t seed = 1;
  int num_threads = 0;
  // Early stopping: keep both networks' parameters from the report with the least validation
  // objective instead of the last report's. The objective is the training objective's terms on
  // the validation rows, each in its network's output units squared: the first network's
  // validation loss, plus the second's when second validation rows are passed, plus
  // pair_weight times the consistency term's. (The training objective divides each term by its
  // network's output variance to condition the optimisation; the pair's networks output the
  // same quantity, so the validation objective sums them as they are.) Needs validation rows of
  // the first network and of the consistency term (refused otherwise). Reads nothing but the
  // validation rows passed, so it is as truth-free as they are.
  bool keep_least_validation = false;
  bool show_progress = true;
  std::string progress_label = "train-joint";
  // steps, steps_per_report and batches >= 1, learning_rate > 0, pair_weight >= 0 and finite,
  // num_threads >= 0. Names the field.
  Status Check() const;
};

struct MlpPairTrainSummary {
  // Per report interval, the mean over its steps: each supervised loss (mean squared error per
  // output dimension, its network's output units squared) and the consistency term (the first
  // network's output units squared).
  std::vector<double> first_loss, second_loss, pair_loss;
  // Per report interval, on the validation rows passed (empty without them).
  std::vector<double> first_validation_loss, second_validation_loss, pair_validation_loss;
  // The report whose parameters the networks end with: the last, or with keep_least_validation
  // the one of least validation objective (index into the per-report vectors).
  long kept_report = -1;
  long steps = 0;
  double train_s = 0.0;
};

// Each *_validation_rows may be empty (that loss is then not reported).
// Errors: a model without its trained normalisation is not checked (the caller trains first);
// sizes that disagree with the datasets, an empty supervised or consistency row set.
Status TrainMlpPair(const MlpDataset& first_data, const std::vector<long>& first_rows,
                    const std::vector<long>& first_validation_rows, const MlpDataset& second_data,
                    const std::vector<long>& second_rows,
                    const std::vector<long>& second_validation_rows,
                    const MlpPairDataset& pair_data, const std::vector<long>& pair_rows,
                    const std::vector<long>& pair_validation_rows,
                    const MlpPairTrainOptions& options, Mlp* first, Mlp* second,
                    MlpPairTrainSummary* summary);

// Sustained single-precision GEMM rate of this machine through LibTorch (the library the
// networks run on): C = A B with A m x k and B k x n, repeated for at least `min_seconds`;
// returns the median of the repetitions in multiply-adds per second. For throughput ratios.
double MeasureGemmMultiplyAddsPerSecond(int m, int k, int n, double min_seconds);

}  // namespace facedyn::learn
