#include "learn/mlp.h"

#include <ATen/CPUGeneratorImpl.h>
#include <fmt/format.h>
#include <torch/torch.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <mutex>
#include <random>
#include <utility>

#include "core/check.h"
#include "core/progress.h"

namespace facedyn::learn {

namespace {

constexpr char kKindKey[] = "facedyn_model_kind";
constexpr char kConfigKey[] = "facedyn_model_config";
const std::string kAttachmentPrefix = "facedyn_attachment_";

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// Linear layers fc1..fcN (N = hidden_layers + 1) with ReLU between, plus normalisation buffers.
// With the default shape the modules and their initialisation are exactly those of the plain
// network, so the options cost nothing when off.
struct NetImpl : torch::nn::Module {
  explicit NetImpl(const MlpShape& shape)
      : residual(shape.residual),
        dropout(shape.dropout),
        main_inputs(shape.input_size - shape.extra_input_size),
        extra_inputs(shape.extra_input_size),
        extra_layer(shape.extra_input_layer),
        input_mean(register_buffer("input_mean", torch::zeros({shape.input_size}))),
        input_std(register_buffer("input_std", torch::ones({shape.input_size}))),
        output_mean(register_buffer("output_mean", torch::zeros({shape.output_size}))),
        output_std(register_buffer("output_std", torch::ones({shape.output_size}))) {
    int in = main_inputs;
    for (int k = 0; k <= shape.hidden_layers; ++k) {
      const int out = k < shape.hidden_layers ? shape.hidden_units : shape.output_size;
      // Layer index k is hidden layer k + 1; the extra inputs join hidden layer extra_layer.
      const int extra = extra_inputs > 0 && k + 1 == extra_layer ? extra_inputs : 0;
      layers.push_back(register_module("fc" + std::to_string(k + 1), torch::nn::Linear(in + extra, out)));
      in = out;
    }
    if (shape.linear_skip) {
      skip = register_module(
          "skip", torch::nn::Linear(
                      torch::nn::LinearOptions(shape.input_size, shape.output_size).bias(false)));
      torch::NoGradGuard no_grad;
      skip->weight.zero_();  // starts as the plain MLP
    }
  }

  torch::Tensor ForwardNormalised(const torch::Tensor& input) {
    torch::Tensor x = extra_inputs > 0 ? input.narrow(1, 0, main_inputs) : input;
    const size_t hidden = layers.size() - 1;
    for (size_t k = 0; k < layers.size(); ++k) {
      torch::Tensor in = x;
      if (extra_inputs > 0 && static_cast<int>(k) + 1 == extra_layer) {
        in = torch::cat({x, input.narrow(1, main_inputs, extra_inputs)}, 1);
      }
      torch::Tensor y = layers[k]->forward(in);
      if (k < hidden) {
        y = torch::relu(y);
        if (residual && k > 0) y = y + x;
        if (dropout > 0 && is_training()) {
          // Inverted dropout from the trainer's own generator, so a seed reproduces the run
          // whatever else drew from LibTorch's global generator.
          y = dropout_generator ? y * torch::bernoulli(torch::full_like(y, 1.0 - dropout), *dropout_generator) /
                                          (1.0 - dropout)
                                : torch::dropout(y, dropout, true);
        }
      }
      x = y;
    }
    if (!skip.is_empty()) x = x + skip->forward(input);
    return x;
  }
  torch::Tensor Forward(const torch::Tensor& raw) {
    return ForwardNormalised((raw - input_mean) / input_std) * output_std + output_mean;
  }

  bool residual;
  double dropout;
  c10::optional<at::Generator> dropout_generator;  // set by TrainMlp
  int main_inputs, extra_inputs, extra_layer;
  std::vector<torch::nn::Linear> layers;
  torch::nn::Linear skip{nullptr};
  torch::Tensor input_mean, input_std, output_mean, output_std;
};
TORCH_MODULE(Net);

// A column-major (rows x cols) Eigen matrix seen as a row-major cols x rows tensor: no copy.
torch::Tensor AsRowMajorTensor(const Eigen::MatrixXf& matrix) {
  return torch::from_blob(const_cast<float*>(matrix.data()), {matrix.cols(), matrix.rows()},
                          torch::kFloat32);
}

Json ShapeToJson(const MlpShape& shape) {
  return {{"input_size", shape.input_size},
          {"hidden_units", shape.hidden_units},
          {"hidden_layers", shape.hidden_layers},
          {"output_size", shape.output_size},
          {"linear_skip", shape.linear_skip},
          {"residual", shape.residual},
          {"dropout", shape.dropout},
          {"extra_input_size", shape.extra_input_size},
          {"extra_input_layer", shape.extra_input_layer}};
}

}  // namespace

Status MlpShape::Check() const {
  if (input_size < 1) return InvalidArgumentError("input_size must be >= 1");
  if (hidden_units < 1) return InvalidArgumentError("hidden_units must be >= 1");
  if (hidden_layers < 1) return InvalidArgumentError("hidden_layers must be >= 1");
  if (output_size < 1) return InvalidArgumentError("output_size must be >= 1");
  if (!(dropout >= 0 && dropout < 1)) return InvalidArgumentError("dropout must be in [0, 1)");
  if (extra_input_size < 0 || extra_input_size >= input_size) {
    return InvalidArgumentError("extra_input_size must be in [0, input_size)");
  }
  if (extra_input_size == 0 && extra_input_layer != 0) {
    return InvalidArgumentError("extra_input_layer must be 0 without extra inputs");
  }
  if (extra_input_size > 0 && (extra_input_layer < 2 || extra_input_layer > hidden_layers)) {
    return InvalidArgumentError("extra_input_layer must be in 2..hidden_layers (the first hidden "
                                "layer already sees every other input)");
  }
  return Status::Ok();
}

double MlpShape::ForwardMultiplyAdds() const {
  double total = static_cast<double>(input_size) * hidden_units;  // the extra inputs count once
  total += static_cast<double>(hidden_layers - 1) * hidden_units * hidden_units;
  total += static_cast<double>(hidden_units) * output_size;
  if (linear_skip) total += static_cast<double>(input_size) * output_size;
  return total;
}

namespace {

// Guards LibTorch's process-wide generator, which initialises every new network's weights.
std::mutex& GlobalGeneratorMutex() {
  static std::mutex mutex;
  return mutex;
}

}  // namespace

struct Mlp::Impl {
  MlpShape shape;
  Net net{nullptr};
};

Mlp::Mlp() = default;
Mlp::~Mlp() = default;
Mlp::Mlp(Mlp&&) noexcept = default;
Mlp& Mlp::operator=(Mlp&&) noexcept = default;

StatusOr<Mlp> Mlp::Create(const MlpShape& shape, uint64_t seed) {
  FACEDYN_RETURN_IF_ERROR(shape.Check());
  Mlp model;
  model.impl_ = std::make_unique<Impl>();
  model.impl_->shape = shape;
  {
    // The initial weights come from LibTorch's process-wide generator: seeding it and drawing
    // them must not interleave with another thread's, or networks created at once (the demo
    // trains independent ones side by side) would depend on the threads' timing.
    std::lock_guard<std::mutex> lock(GlobalGeneratorMutex());
    torch::manual_seed(seed);
    model.impl_->net = Net(shape);
  }
  model.impl_->net->eval();
  return model;
}

Mlp Mlp::Clone() const {
  FACEDYN_CHECK(valid(), "Clone() on an empty Mlp");
  Mlp copy;
  copy.impl_ = std::make_unique<Impl>();
  copy.impl_->shape = impl_->shape;
  {
    // Constructing draws initial weights from the global generator (overwritten below): under
    // the same lock as Create, so a clone never shifts a concurrent Create's draws.
    std::lock_guard<std::mutex> lock(GlobalGeneratorMutex());
    copy.impl_->net = Net(impl_->shape);
  }
  torch::NoGradGuard no_grad;
  auto source_parameters = impl_->net->named_parameters(/*recurse=*/true);
  for (auto& entry : copy.impl_->net->named_parameters(/*recurse=*/true)) {
    entry.value().copy_(source_parameters[entry.key()]);
  }
  auto source_buffers = impl_->net->named_buffers(/*recurse=*/true);
  for (auto& entry : copy.impl_->net->named_buffers(/*recurse=*/true)) {
    entry.value().copy_(source_buffers[entry.key()]);
  }
  copy.impl_->net->eval();
  return copy;
}

const MlpShape& Mlp::shape() const {
  FACEDYN_CHECK(valid(), "shape() on an empty Mlp");
  return impl_->shape;
}

Status Mlp::Save(const std::string& path, const std::string& kind, Json config,
                 const MlpAttachments& attachments) const {
  FACEDYN_CHECK(valid(), "Save() on an empty Mlp");
  FACEDYN_CHECK(config.is_object(), "Mlp::Save: config must be a JSON object");
  config["mlp"] = ShapeToJson(impl_->shape);
  Json listed = Json::object();
  for (const auto& [name, matrix] : attachments) listed[name] = {matrix.rows(), matrix.cols()};
  config["attachments"] = listed;
  const std::string temporary = path + ".tmp";
  try {
    torch::serialize::OutputArchive archive;
    impl_->net->save(archive);
    for (const auto& [name, matrix] : attachments) {
      // A copy: the archive keeps the tensor, and the matrix is const.
      torch::Tensor flat = torch::empty({static_cast<int64_t>(matrix.size())}, torch::kFloat32);
      std::memcpy(flat.data_ptr<float>(), matrix.data(), sizeof(float) * matrix.size());
      archive.write(kAttachmentPrefix + name, flat);
    }
    archive.write(kKindKey, c10::IValue(kind));
    archive.write(kConfigKey, c10::IValue(config.dump()));
    archive.save_to(temporary);
  } catch (const std::exception& e) {
    std::remove(temporary.c_str());
    return UnavailableError(path + ": cannot write the model: " + e.what());
  }
  if (std::rename(temporary.c_str(), path.c_str()) != 0) {
    std::remove(temporary.c_str());
    return UnavailableError(path + ": cannot rename " + temporary + " into place");
  }
  return Status::Ok();
}

StatusOr<Mlp> Mlp::Load(const std::string& path, const std::string& expected_kind, Json* config,
                        MlpAttachments* attachments) {
  FACEDYN_CHECK(config != nullptr, "Mlp::Load: config is null");
  try {
    torch::serialize::InputArchive archive;
    archive.load_from(path);
    c10::IValue kind_value, config_value;
    if (!archive.try_read(kKindKey, kind_value) || !kind_value.isString() ||
        !archive.try_read(kConfigKey, config_value) || !config_value.isString()) {
      return DataLossError(path + ": no " + kKindKey + "/" + kConfigKey +
                           " entries (not a facedyn model)");
    }
    if (kind_value.toStringRef() != expected_kind) {
      return DataLossError(path + ": is a " + kind_value.toStringRef() + " model, expected a " +
                           expected_kind + " model");
    }
    try {
      *config = Json::parse(config_value.toStringRef());
    } catch (const std::exception& e) {
      return DataLossError(path + ": " + kConfigKey + " is not JSON: " + e.what());
    }
    MlpShape shape;
    try {
      const Json& mlp = config->at("mlp");
      shape.input_size = mlp.at("input_size").get<int>();
      shape.hidden_units = mlp.at("hidden_units").get<int>();
      shape.hidden_layers = mlp.at("hidden_layers").get<int>();
      shape.output_size = mlp.at("output_size").get<int>();
      // Absent in files written before each option existed.
      shape.linear_skip = mlp.value("linear_skip", false);
      shape.residual = mlp.value("residual", false);
      shape.dropout = mlp.value("dropout", 0.0);
      shape.extra_input_size = mlp.value("extra_input_size", 0);
      shape.extra_input_layer = mlp.value("extra_input_layer", 0);
    } catch (const std::exception& e) {
      return DataLossError(path + ": bad mlp shape in the config: " + e.what());
    }
    if (Status status = shape.Check(); !status.ok()) return status.WithContext(path);
    Mlp model;
    model.impl_ = std::make_unique<Impl>();
    model.impl_->shape = shape;
    model.impl_->net = Net(shape);
    // Module::load replaces each tensor with the stored one whatever its shape: check them.
    std::vector<std::vector<int64_t>> expected;
    for (const auto& item : model.impl_->net->named_parameters()) {
      expected.push_back(item.value().sizes().vec());
    }
    for (const auto& item : model.impl_->net->named_buffers()) {
      expected.push_back(item.value().sizes().vec());
    }
    model.impl_->net->load(archive);
    size_t k = 0;
    for (const auto& item : model.impl_->net->named_parameters()) {
      if (item.value().sizes().vec() != expected[k++]) {
        return DataLossError(path + ": tensor " + item.key() + " has the wrong shape");
      }
    }
    for (const auto& item : model.impl_->net->named_buffers()) {
      if (item.value().sizes().vec() != expected[k++]) {
        return DataLossError(path + ": tensor " + item.key() + " has the wrong shape");
      }
    }
    if (attachments != nullptr) {
      attachments->clear();
      const Json listed = config->value("attachments", Json::object());
      if (!listed.is_object()) return DataLossError(path + ": \"attachments\" is not an object");
      for (const auto& [name, size] : listed.items()) {
        if (!size.is_array() || size.size() != 2 || !size[0].is_number_integer() ||
            !size[1].is_number_integer() || size[0].get<int64_t>() < 0 ||
            size[1].get<int64_t>() < 0) {
          return DataLossError(path + ": attachment " + name + " has no [rows, cols]");
        }
        const int64_t rows = size[0].get<int64_t>(), cols = size[1].get<int64_t>();
        torch::Tensor flat;
        if (!archive.try_read(kAttachmentPrefix + name, flat)) {
          return DataLossError(path + ": attachment " + name + " is listed but missing");
        }
        if (flat.scalar_type() != torch::kFloat32 || flat.dim() != 1 ||
            flat.numel() != rows * cols) {
          return DataLossError(path + ": attachment " + name + " is not " + std::to_string(rows) +
                               " x " + std::to_string(cols) + " floats");
        }
        flat = flat.contiguous();
        Eigen::MatrixXf matrix(rows, cols);
        std::memcpy(matrix.data(), flat.data_ptr<float>(), sizeof(float) * matrix.size());
        (*attachments)[name] = std::move(matrix);
      }
    }
    model.impl_->net->eval();
    return model;
  } catch (const std::exception& e) {
    return DataLossError(path + ": cannot read the model: " + e.what());
  }
}

Eigen::MatrixXf Mlp::Predict(const Eigen::MatrixXf& inputs) const {
  const MlpShape& shape = this->shape();
  FACEDYN_CHECK(inputs.rows() == shape.input_size,
                "Predict: inputs have " + std::to_string(inputs.rows()) + " rows, expected " +
                    std::to_string(shape.input_size));
  Eigen::MatrixXf out(shape.output_size, inputs.cols());
  if (inputs.cols() == 0) return out;
  torch::NoGradGuard no_grad;
  const torch::Tensor output = impl_->net->Forward(AsRowMajorTensor(inputs)).contiguous();
  std::memcpy(out.data(), output.data_ptr<float>(), sizeof(float) * out.size());
  return out;
}

void Mlp::SetNormalisation(const Eigen::VectorXf& input_mean, const Eigen::VectorXf& input_std,
                           const Eigen::VectorXf& output_mean, const Eigen::VectorXf& output_std) {
  const MlpShape& shape = this->shape();
  FACEDYN_CHECK(input_mean.size() == shape.input_size && input_std.size() == shape.input_size &&
                    output_mean.size() == shape.output_size &&
                    output_std.size() == shape.output_size,
                "SetNormalisation: wrong sizes");
  FACEDYN_CHECK(input_std.minCoeff() > 0 && output_std.minCoeff() > 0,
                "SetNormalisation: standard deviations must be > 0");
  torch::NoGradGuard no_grad;
  auto copy = [](torch::Tensor& dst, const Eigen::VectorXf& src) {
    std::memcpy(dst.data_ptr<float>(), src.data(), sizeof(float) * src.size());
  };
  copy(impl_->net->input_mean, input_mean);
  copy(impl_->net->input_std, input_std);
  copy(impl_->net->output_mean, output_mean);
  copy(impl_->net->output_std, output_std);
}

std::vector<float> Mlp::FlatParameters() const {
  FACEDYN_CHECK(valid(), "FlatParameters() on an empty Mlp");
  std::vector<float> flat;
  auto append = [&flat](const torch::Tensor& tensor) {
    const torch::Tensor t = tensor.detach().contiguous();
    const float* p = t.data_ptr<float>();
    flat.insert(flat.end(), p, p + t.numel());
  };
  for (const auto& item : impl_->net->named_parameters()) append(item.value());
  for (const auto& item : impl_->net->named_buffers()) append(item.value());
  return flat;
}

Status MlpTrainOptions::Check() const {
  if (epochs < 1) return InvalidArgumentError("epochs must be >= 1");
  if (batch_size < 1) return InvalidArgumentError("batch_size must be >= 1");
  if (optimizer_steps < 0) return InvalidArgumentError("optimizer_steps must be >= 0");
  if (!(learning_rate > 0)) return InvalidArgumentError("learning_rate must be > 0");
  if (!(final_learning_rate_fraction > 0 && final_learning_rate_fraction <= 1)) {
    return InvalidArgumentError("final_learning_rate_fraction must be in (0, 1]");
  }
  if (!(weight_decay >= 0)) return InvalidArgumentError("weight_decay must be >= 0");
  if (!(input_noise_std >= 0)) return InvalidArgumentError("input_noise_std must be >= 0");
  if (num_threads < 0) return InvalidArgumentError("num_threads must be >= 0");
  return Status::Ok();
}

// Friend of Mlp: reaches the network for the optimisation.
struct MlpTrainer {
  static Net& NetOf(Mlp& model) { return model.impl_->net; }
};

namespace {

// Mean and standard deviation per dimension of the gathered rows (double accumulation, in
// batches so the assembled rows never all live at once).
void FitNormalisation(const MlpDataset& data, const std::vector<long>& rows, long batch,
                      Eigen::VectorXf* in_mean, Eigen::VectorXf* in_std, Eigen::VectorXf* out_mean,
                      Eigen::VectorXf* out_std) {
  const int ni = data.input_size();
  const int no = data.output_size();
  Eigen::VectorXd sum = Eigen::VectorXd::Zero(ni), sum_sq = Eigen::VectorXd::Zero(ni);
  Eigen::VectorXd out_sum = Eigen::VectorXd::Zero(no), out_sum_sq = Eigen::VectorXd::Zero(no);
  Eigen::MatrixXf inputs, targets;
  for (size_t begin = 0; begin < rows.size(); begin += static_cast<size_t>(batch)) {
    const long n = static_cast<long>(std::min(rows.size() - begin, static_cast<size_t>(batch)));
    data.Gather(rows.data() + begin, n, &inputs, &targets);
    const Eigen::MatrixXd x = inputs.cast<double>();
    const Eigen::MatrixXd y = targets.cast<double>();
    sum += x.rowwise().sum();
    sum_sq += x.cwiseAbs2().rowwise().sum();
    out_sum += y.rowwise().sum();
    out_sum_sq += y.cwiseAbs2().rowwise().sum();
  }
  const double n = static_cast<double>(rows.size());
  auto fill = [n](const Eigen::VectorXd& s, const Eigen::VectorXd& s2, Eigen::VectorXf* mean,
                  Eigen::VectorXf* sd) {
    mean->resize(s.size());
    sd->resize(s.size());
    for (Eigen::Index d = 0; d < s.size(); ++d) {
      const double m = s[d] / n;
      const double deviation = std::sqrt(std::max(0.0, s2[d] / n - m * m));
      (*mean)[d] = static_cast<float>(m);
      (*sd)[d] = static_cast<float>(deviation > 1e-9 ? deviation : 1.0);  // constants: centred
    }
  };
  fill(sum, sum_sq, in_mean, in_std);
  fill(out_sum, out_sum_sq, out_mean, out_std);
}

}  // namespace

Status TrainMlp(const MlpDataset& data, const std::vector<long>& train_rows,
                const std::vector<long>& validation_rows, const MlpTrainOptions& options,
                Mlp* model, MlpTrainSummary* summary) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  FACEDYN_CHECK(model != nullptr && model->valid(), "TrainMlp: no model");
  if (train_rows.empty()) return FailedPreconditionError("TrainMlp: no training rows");
  const MlpShape& shape = model->shape();
  if (shape.input_size != data.input_size() || shape.output_size != data.output_size()) {
    return InvalidArgumentError("TrainMlp: the model is " + std::to_string(shape.input_size) +
                                " -> " + std::to_string(shape.output_size) + ", the data " +
                                std::to_string(data.input_size()) + " -> " +
                                std::to_string(data.output_size()));
  }
  if (options.num_threads > 0) torch::set_num_threads(options.num_threads);
  const long batch = options.batch_size;

  Eigen::VectorXf in_mean, in_std, out_mean, out_std;
  FitNormalisation(data, train_rows, std::max(batch, 4096L), &in_mean, &in_std, &out_mean,
                   &out_std);
  model->SetNormalisation(in_mean, in_std, out_mean, out_std);
  const Eigen::VectorXf in_inv_std = in_std.cwiseInverse();
  const Eigen::VectorXf out_inv_std = out_std.cwiseInverse();
  auto normalise = [&](Eigen::MatrixXf* inputs, Eigen::MatrixXf* targets) {
    inputs->colwise() -= in_mean;
    *inputs = in_inv_std.asDiagonal() * *inputs;
    targets->colwise() -= out_mean;
    *targets = out_inv_std.asDiagonal() * *targets;
  };

  // Per-dimension loss weights (1 x output_size): std_d^2 / mean(std^2) in output units, else 1.
  // The reported losses are multiplied back by mean(std^2), so they are in units^2.
  const double mean_variance = out_std.cwiseAbs2().cast<double>().mean();
  torch::Tensor loss_weights =
      torch::ones({1, static_cast<long>(out_std.size())}, torch::kFloat32);
  double report_scale = 1.0;
  if (options.loss_in_output_units && mean_variance > 0) {
    for (long d = 0; d < out_std.size(); ++d) {
      loss_weights[0][d] = static_cast<float>(out_std[d] * out_std[d] / mean_variance);
    }
    report_scale = mean_variance;
  }
  auto weighted_mse = [&](const torch::Tensor& predicted, const torch::Tensor& target) {
    return ((predicted - target).square() * loss_weights).mean();
  };

  Net& net = MlpTrainer::NetOf(*model);
  net->train();
  // Plain Adam without weight decay (the paper's, and bitwise what facedyn always trained with);
  // AdamW with it (Adam's own weight_decay adds an L2 gradient that the adaptive step then
  // divides by the gradient scale, so the weights with the largest gradients decay least).
  std::unique_ptr<torch::optim::Optimizer> optimizer;
  if (options.weight_decay > 0) {
    optimizer = std::make_unique<torch::optim::AdamW>(
        net->parameters(),
        torch::optim::AdamWOptions(options.learning_rate).weight_decay(options.weight_decay));
  } else {
    optimizer = std::make_unique<torch::optim::Adam>(
        net->parameters(), torch::optim::AdamOptions(options.learning_rate));
  }
  // Its own generator, so the noise does not depend on what else drew from LibTorch's global one.
  at::Generator noise_generator = at::detail::createCPUGenerator(options.seed);
  net->dropout_generator = at::detail::createCPUGenerator(options.seed ^ 0x9e3779b97f4a7c15ULL);
  MlpTrainSummary local;
  local.training_rows = static_cast<long>(train_rows.size());
  local.validation_rows = static_cast<long>(validation_rows.size());
  // A step budget fixes the epochs (the last one cut short); otherwise whole epochs.
  const long batches_per_epoch = (static_cast<long>(train_rows.size()) + batch - 1) / batch;
  const long step_budget = options.optimizer_steps > 0
                               ? options.optimizer_steps
                               : static_cast<long>(options.epochs) * batches_per_epoch;
  const int epochs = static_cast<int>((step_budget + batches_per_epoch - 1) / batches_per_epoch);
  Progress progress(options.progress_label, epochs,
                    options.show_progress ? ProgressMode::kAuto : ProgressMode::kSilent);
  std::vector<long> order = train_rows;
  std::mt19937_64 rng(options.seed);
  Eigen::MatrixXf inputs, targets;
  long rows_trained = 0;
  const auto start = std::chrono::steady_clock::now();
  for (int epoch = 0; epoch < epochs; ++epoch) {
    const double lr =
        options.learning_rate *
        std::pow(options.final_learning_rate_fraction,
                 epochs > 1 ? static_cast<double>(epoch) / (epochs - 1) : 0.0);
    for (auto& group : optimizer->param_groups()) group.options().set_lr(lr);
    std::shuffle(order.begin(), order.end(), rng);
    double loss_sum = 0.0;
    long epoch_rows = 0;
    for (size_t begin = 0; begin < order.size() && local.optimizer_steps < step_budget;
         begin += static_cast<size_t>(batch)) {
      const long n = static_cast<long>(std::min(order.size() - begin, static_cast<size_t>(batch)));
      data.Gather(order.data() + begin, n, &inputs, &targets);
      normalise(&inputs, &targets);
      optimizer->zero_grad();
      torch::Tensor batch_inputs = AsRowMajorTensor(inputs);
      if (options.input_noise_std > 0) {
        batch_inputs = batch_inputs + options.input_noise_std *
                                          torch::randn(batch_inputs.sizes(), noise_generator);
      }
      const torch::Tensor loss =
          weighted_mse(net->ForwardNormalised(batch_inputs), AsRowMajorTensor(targets));
      loss.backward();
      optimizer->step();
      ++local.optimizer_steps;
      loss_sum += loss.item<double>() * static_cast<double>(n);
      epoch_rows += n;
    }
    rows_trained += epoch_rows;
    local.epochs = epoch + 1;
    local.train_loss.push_back(report_scale * loss_sum / static_cast<double>(epoch_rows));
    char status[96];
    if (!validation_rows.empty()) {
      torch::NoGradGuard no_grad;
      net->eval();  // no dropout when validating
      double validation_sum = 0.0;
      const long eval_batch = std::max(batch, 4096L);
      for (size_t begin = 0; begin < validation_rows.size();
           begin += static_cast<size_t>(eval_batch)) {
        const long n = static_cast<long>(
            std::min(validation_rows.size() - begin, static_cast<size_t>(eval_batch)));
        data.Gather(validation_rows.data() + begin, n, &inputs, &targets);
        normalise(&inputs, &targets);
        validation_sum += weighted_mse(net->ForwardNormalised(AsRowMajorTensor(inputs)),
                                       AsRowMajorTensor(targets))
                              .item<double>() *
                          static_cast<double>(n);
      }
      net->train();
      local.validation_loss.push_back(report_scale * validation_sum /
                                      static_cast<double>(validation_rows.size()));
      std::snprintf(status, sizeof(status), "loss %.4g val %.4g", local.train_loss.back(),
                    local.validation_loss.back());
    } else {
      std::snprintf(status, sizeof(status), "loss %.4g", local.train_loss.back());
    }
    progress.Update(epoch + 1, status);
  }
  progress.Finish();
  net->eval();
  net->dropout_generator.reset();
  local.train_s = SecondsSince(start);
  local.rows_per_s =
      local.train_s > 0 ? static_cast<double>(rows_trained) / local.train_s : 0.0;
  if (summary != nullptr) *summary = std::move(local);
  return Status::Ok();
}

Status MlpPairTrainOptions::Check() const {
  if (steps < 1) return InvalidArgumentError("steps must be >= 1");
  if (steps_per_report < 1) return InvalidArgumentError("steps_per_report must be >= 1");
  if (!(learning_rate > 0)) return InvalidArgumentError("learning_rate must be > 0");
  if (first_batch < 1) return InvalidArgumentError("first_batch must be >= 1");
  if (second_batch < 1) return InvalidArgumentError("second_batch must be >= 1");
  if (pair_batch < 1) return InvalidArgumentError("pair_batch must be >= 1");
  if (!(std::isfinite(pair_weight) && pair_weight >= 0)) {
    return InvalidArgumentError("pair_weight must be finite and >= 0");
  }
  if (num_threads < 0) return InvalidArgumentError("num_threads must be >= 0");
  return Status::Ok();
}

namespace {

// Shuffled passes over a row set, one batch at a time (reshuffled at the end of each pass).
class RowCycler {
 public:
  RowCycler(const std::vector<long>& rows, uint64_t seed) : order_(rows), rng_(seed) {
    std::shuffle(order_.begin(), order_.end(), rng_);
  }
  // The next min(n, size) rows, in *out.
  void Next(long n, std::vector<long>* out) {
    out->clear();
    n = std::min<long>(n, static_cast<long>(order_.size()));
    while (static_cast<long>(out->size()) < n) {
      if (next_ == order_.size()) {
        std::shuffle(order_.begin(), order_.end(), rng_);
        next_ = 0;
      }
      out->push_back(order_[next_++]);
    }
  }

 private:
  std::vector<long> order_;
  std::mt19937_64 rng_;
  size_t next_ = 0;
};

// The mean of output_std^2: the squared error in output units divided by it is TrainMlp's
// loss in output units (loss_in_output_units), so fine-tuning keeps the step scale.
double MeanOutputVariance(Net& net) { return net->output_std.square().mean().item<double>(); }

}  // namespace

Status TrainMlpPair(const MlpDataset& first_data, const std::vector<long>& first_rows,
                    const std::vector<long>& first_validation_rows, const MlpDataset& second_data,
                    const std::vector<long>& second_rows,
                    const std::vector<long>& second_validation_rows,
                    const MlpPairDataset& pair_data, const std::vector<long>& pair_rows,
                    const std::vector<long>& pair_validation_rows,
                    const MlpPairTrainOptions& options, Mlp* first, Mlp* second,
                    MlpPairTrainSummary* summary) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  FACEDYN_CHECK(first != nullptr && first->valid() && second != nullptr && second->valid(),
                "TrainMlpPair: no model");
  const MlpShape& f_shape = first->shape();
  const MlpShape& h_shape = second->shape();
  auto mismatch = [](const std::string& what, int model, int data) {
    return InvalidArgumentError(
        fmt::format("TrainMlpPair: {}: the model has {}, the data {}", what, model, data));
  };
  if (f_shape.input_size != first_data.input_size()) {
    return mismatch("first inputs", f_shape.input_size, first_data.input_size());
  }
  if (f_shape.output_size != first_data.output_size()) {
    return mismatch("first outputs", f_shape.output_size, first_data.output_size());
  }
  if (h_shape.input_size != second_data.input_size()) {
    return mismatch("second inputs", h_shape.input_size, second_data.input_size());
  }
  if (h_shape.output_size != second_data.output_size()) {
    return mismatch("second outputs", h_shape.output_size, second_data.output_size());
  }
  if (f_shape.input_size != pair_data.first_input_size()) {
    return mismatch("consistency rows' first inputs", f_shape.input_size,
                    pair_data.first_input_size());
  }
  if (h_shape.input_size != pair_data.second_input_size()) {
    return mismatch("consistency rows' second inputs", h_shape.input_size,
                    pair_data.second_input_size());
  }
  if (h_shape.output_size != pair_data.group_size() * f_shape.output_size) {
    return mismatch("second outputs for a group", h_shape.output_size,
                    pair_data.group_size() * f_shape.output_size);
  }
  if (first_rows.empty()) return FailedPreconditionError("TrainMlpPair: no first training rows");
  if (second_rows.empty()) {
    return FailedPreconditionError("TrainMlpPair: no second training rows");
  }
  if (pair_rows.empty()) return FailedPreconditionError("TrainMlpPair: no consistency rows");
  if (options.keep_least_validation &&
      (first_validation_rows.empty() || pair_validation_rows.empty())) {
    return FailedPreconditionError(
        "TrainMlpPair: keep_least_validation needs validation rows of the first network and of "
        "the consistency term");
  }
  if (options.num_threads > 0) torch::set_num_threads(options.num_threads);

  Net& f = MlpTrainer::NetOf(*first);
  Net& h = MlpTrainer::NetOf(*second);
  const double f_scale = MeanOutputVariance(f);
  const double h_scale = MeanOutputVariance(h);
  const int group = pair_data.group_size();
  const long f_outputs = f_shape.output_size;

  // The second network always trains on its own supervised loss; pair_trains_second only
  // keeps the consistency term's gradient from reaching it (below).
  std::vector<torch::Tensor> parameters = f->parameters();
  for (const torch::Tensor& p : h->parameters()) parameters.push_back(p);
  torch::optim::Adam optimizer(parameters, torch::optim::AdamOptions(options.learning_rate));
  f->train();
  h->train();
  f->dropout_generator = at::detail::createCPUGenerator(options.seed ^ 0x9e3779b97f4a7c15ULL);
  h->dropout_generator = at::detail::createCPUGenerator(options.seed ^ 0x7f4a7c159e3779b9ULL);

  RowCycler f_cycler(first_rows, options.seed);
  RowCycler h_cycler(second_rows, options.seed + 1);
  RowCycler pair_cycler(pair_rows, options.seed + 2);
  std::vector<long> batch_rows;
  Eigen::MatrixXf inputs, targets, pair_first, pair_second;

  auto supervised = [](Net& net, const Eigen::MatrixXf& x, const Eigen::MatrixXf& y, double scale) {
    return (net->Forward(AsRowMajorTensor(x)) - AsRowMajorTensor(y)).square().mean() / scale;
  };
  auto consistency = [&](const Eigen::MatrixXf& x_first, const Eigen::MatrixXf& x_second,
                         bool second_gradient) {
    const torch::Tensor f_out = f->Forward(AsRowMajorTensor(x_first));  // (n * group) x m
    torch::Tensor h_out;
    if (second_gradient) {
      h_out = h->Forward(AsRowMajorTensor(x_second));
    } else {
      torch::NoGradGuard no_grad;
      h_out = h->Forward(AsRowMajorTensor(x_second));
    }
    // n x (group * m), row-major: member i's outputs are columns [i * m, (i + 1) * m).
    const torch::Tensor h_by_member = h_out.reshape({-1, f_outputs});
    return (f_out - h_by_member).square().mean() / f_scale;
  };

  MlpPairTrainSummary local;
  // keep_least_validation: the best report's parameters so far (copies, both networks').
  double best_objective = std::numeric_limits<double>::infinity();
  std::vector<torch::Tensor> best_parameters;
  const long reports = (options.steps + options.steps_per_report - 1) / options.steps_per_report;
  Progress progress(options.progress_label, reports,
                    options.show_progress ? ProgressMode::kAuto : ProgressMode::kSilent);
  const auto start = std::chrono::steady_clock::now();
  for (long report = 0; report < reports; ++report) {
    double f_sum = 0.0, h_sum = 0.0, pair_sum = 0.0;
    long steps = 0;
    for (; steps < options.steps_per_report && local.steps < options.steps; ++steps) {
      optimizer.zero_grad();
      f_cycler.Next(options.first_batch, &batch_rows);
      first_data.Gather(batch_rows.data(), static_cast<long>(batch_rows.size()), &inputs, &targets);
      const torch::Tensor f_loss = supervised(f, inputs, targets, f_scale);
      h_cycler.Next(options.second_batch, &batch_rows);
      second_data.Gather(batch_rows.data(), static_cast<long>(batch_rows.size()), &inputs,
                         &targets);
      const torch::Tensor h_loss = supervised(h, inputs, targets, h_scale);
      pair_cycler.Next(options.pair_batch, &batch_rows);
      pair_data.Gather(batch_rows.data(), static_cast<long>(batch_rows.size()), &pair_first,
                       &pair_second);
      const torch::Tensor pair_loss =
          consistency(pair_first, pair_second, options.pair_trains_second);
      const torch::Tensor loss = f_loss + h_loss + options.pair_weight * pair_loss;
      loss.backward();
      optimizer.step();
      ++local.steps;
      f_sum += f_loss.item<double>();
      h_sum += h_loss.item<double>();
      pair_sum += pair_loss.item<double>();
    }
    local.first_loss.push_back(f_scale * f_sum / static_cast<double>(steps));
    local.second_loss.push_back(h_scale * h_sum / static_cast<double>(steps));
    local.pair_loss.push_back(f_scale * pair_sum / static_cast<double>(steps));
    std::string status = fmt::format("F {:.4g} H {:.4g} cycle {:.4g}", local.first_loss.back(),
                                     local.second_loss.back(), local.pair_loss.back());
    if (!first_validation_rows.empty() || !second_validation_rows.empty() ||
        !pair_validation_rows.empty()) {
      torch::NoGradGuard no_grad;
      f->eval();
      h->eval();
      constexpr long kEvalBatch = 4096;
      // A network's mean squared error per output over its validation rows, in its units.
      auto validation_loss = [&](Net& net, const MlpDataset& data, const std::vector<long>& rows) {
        double sum = 0.0;
        for (size_t begin = 0; begin < rows.size(); begin += kEvalBatch) {
          const long n =
              static_cast<long>(std::min(rows.size() - begin, static_cast<size_t>(kEvalBatch)));
          data.Gather(rows.data() + begin, n, &inputs, &targets);
          sum += supervised(net, inputs, targets, 1.0).item<double>() * static_cast<double>(n);
        }
        return sum / static_cast<double>(rows.size());
      };
      if (!first_validation_rows.empty()) {
        local.first_validation_loss.push_back(
            validation_loss(f, first_data, first_validation_rows));
        status += fmt::format(" val F {:.4g}", local.first_validation_loss.back());
      }
      if (!second_validation_rows.empty()) {
        local.second_validation_loss.push_back(
            validation_loss(h, second_data, second_validation_rows));
        status += fmt::format(" val H {:.4g}", local.second_validation_loss.back());
      }
      if (!pair_validation_rows.empty()) {
        const long eval_groups = std::max<long>(1, kEvalBatch / std::max(1, group));
        double sum = 0.0;
        for (size_t begin = 0; begin < pair_validation_rows.size(); begin += eval_groups) {
          const long n = static_cast<long>(
              std::min(pair_validation_rows.size() - begin, static_cast<size_t>(eval_groups)));
          pair_data.Gather(pair_validation_rows.data() + begin, n, &pair_first, &pair_second);
          sum += consistency(pair_first, pair_second, false).item<double>() * f_scale *
                 static_cast<double>(n);
        }
        local.pair_validation_loss.push_back(sum /
                                             static_cast<double>(pair_validation_rows.size()));
        status += fmt::format(" val cycle {:.4g}", local.pair_validation_loss.back());
      }
      if (options.keep_least_validation) {
        const double objective =
            local.first_validation_loss.back() +
            (second_validation_rows.empty() ? 0.0 : local.second_validation_loss.back()) +
            options.pair_weight * local.pair_validation_loss.back();
        if (objective < best_objective) {  // strictly: ties keep the earlier report
          best_objective = objective;
          local.kept_report = report;
          best_parameters.clear();
          for (const torch::Tensor& p : parameters) best_parameters.push_back(p.detach().clone());
        }
      }
      f->train();
      h->train();
    }
    progress.Update(report + 1, status);
  }
  progress.Finish();
  if (options.keep_least_validation && local.kept_report >= 0) {
    torch::NoGradGuard no_grad;
    for (size_t i = 0; i < parameters.size(); ++i) parameters[i].copy_(best_parameters[i]);
  } else {
    local.kept_report = reports - 1;
  }
  f->eval();
  h->eval();
  f->dropout_generator.reset();
  h->dropout_generator.reset();
  local.train_s = SecondsSince(start);
  if (summary != nullptr) *summary = std::move(local);
  return Status::Ok();
}

double MeasureGemmMultiplyAddsPerSecond(int m, int k, int n, double min_seconds) {
  torch::NoGradGuard no_grad;
  torch::manual_seed(0);
  const torch::Tensor a = torch::randn({m, k});
  const torch::Tensor b = torch::randn({k, n});
  torch::Tensor c = torch::mm(a, b);  // warm-up
  std::vector<double> rates;
  const auto start = std::chrono::steady_clock::now();
  while (rates.size() < 5 || SecondsSince(start) < min_seconds) {
    const auto t0 = std::chrono::steady_clock::now();
    c = torch::mm(a, b);
    const double seconds = SecondsSince(t0);
    rates.push_back(static_cast<double>(m) * k * n / std::max(seconds, 1e-9));
  }
  std::nth_element(rates.begin(), rates.begin() + rates.size() / 2, rates.end());
  return rates[rates.size() / 2];
}

}  // namespace facedyn::learn
