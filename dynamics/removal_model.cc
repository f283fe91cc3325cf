#include "dynamics/removal_model.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <numeric>
#include <random>
#include <utility>

#include <torch/torch.h>

#include "core/json_io.h"
#include "core/progress.h"
#include "dynamics/quasistatic.h"

namespace facedyn::dynamics {

namespace {

constexpr int kRemovalFormatVersion = 1;
constexpr char kConfigKey[] = "facedyn_removal_config";

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

std::string Hex64(uint64_t value) {
  char buffer[17];
  std::snprintf(buffer, sizeof(buffer), "%016llx", static_cast<unsigned long long>(value));
  return buffer;
}

std::string FormatVector(const Eigen::Vector3d& v) {
  char buffer[96];
  std::snprintf(buffer, sizeof(buffer), "(%.4f, %.4f, %.4f)", v.x(), v.y(), v.z());
  return buffer;
}

// The network F with its normalisation buffers: x_n = (x - input_mean) / input_std,
// dx = MLP(x_n) * output_std + output_mean.
struct RemovalNetImpl : torch::nn::Module {
  RemovalNetImpl(int input_size, int hidden_units)
      : fc1(register_module("fc1", torch::nn::Linear(input_size, hidden_units))),
        fc2(register_module("fc2", torch::nn::Linear(hidden_units, hidden_units))),
        fc3(register_module("fc3", torch::nn::Linear(hidden_units, 3))),
        input_mean(register_buffer("input_mean", torch::zeros({input_size}))),
        input_std(register_buffer("input_std", torch::ones({input_size}))),
        output_mean(register_buffer("output_mean", torch::zeros({3}))),
        output_std(register_buffer("output_std", torch::ones({3}))) {}

  torch::Tensor ForwardNormalised(const torch::Tensor& x) {
    return fc3->forward(torch::relu(fc2->forward(torch::relu(fc1->forward(x)))));
  }
  torch::Tensor Forward(const torch::Tensor& raw) {
    return ForwardNormalised((raw - input_mean) / input_std) * output_std + output_mean;
  }

  torch::nn::Linear fc1, fc2, fc3;
  torch::Tensor input_mean, input_std, output_mean, output_std;
};
TORCH_MODULE(RemovalNet);

Json ConfigToJson(const RemovalConfig& config) {
  Json json;
  json["format_version"] = kRemovalFormatVersion;
  json["fps"] = config.features.fps;
  json["window_s"] = config.features.window_s;
  json["window_frames"] = config.features.window_frames();
  json["stretch_step_mm"] = config.features.stretch_step_mm;
  Json landmarks = Json::array();
  for (const SkullLandmark& landmark : config.landmarks) {
    landmarks.push_back({{"name", landmark.name},
                         {"position_in_skull_mm",
                          {landmark.position_in_skull.x(), landmark.position_in_skull.y(),
                           landmark.position_in_skull.z()}}});
  }
  json["landmarks"] = landmarks;
  json["sample_count"] = config.sample_count;
  json["samples_hash"] = Hex64(config.samples_hash);
  json["hidden_units"] = config.hidden_units;
  json["input_size"] = config.input_size();
  json["output_size"] = 3;
  return json;
}

StatusOr<RemovalConfig> ConfigFromJson(const Json& json) {
  try {
    if (json.at("format_version").get<int>() != kRemovalFormatVersion) {
      return DataLossError("format_version " + json.at("format_version").dump() +
                           " is not supported (expected " +
                           std::to_string(kRemovalFormatVersion) + ")");
    }
    RemovalConfig config;
    config.features.fps = json.at("fps").get<double>();
    config.features.window_s = json.at("window_s").get<double>();
    config.features.stretch_step_mm = json.at("stretch_step_mm").get<double>();
    for (const Json& landmark : json.at("landmarks")) {
      const Json& p = landmark.at("position_in_skull_mm");
      config.landmarks.push_back(
          {landmark.at("name").get<std::string>(),
           Eigen::Vector3d(p.at(0).get<double>(), p.at(1).get<double>(), p.at(2).get<double>())});
    }
    config.sample_count = json.at("sample_count").get<int>();
    config.samples_hash = std::stoull(json.at("samples_hash").get<std::string>(), nullptr, 16);
    config.hidden_units = json.at("hidden_units").get<int>();
    FACEDYN_RETURN_IF_ERROR(config.Check());
    if (json.at("window_frames").get<int>() != config.features.window_frames() ||
        json.at("input_size").get<int>() != config.input_size()) {
      return DataLossError("window_frames or input_size disagree with fps, window_s, landmarks");
    }
    return config;
  } catch (const std::exception& e) {
    return DataLossError(std::string("bad removal config: ") + e.what());
  }
}

// Skin-sample values of a per-vertex cache (3V x F): 3 x (F * S), column t * S + i.
Eigen::MatrixXf SampleCache(const PointCache& cache, const std::vector<SurfacePoint>& samples) {
  const int sample_count = static_cast<int>(samples.size());
  Eigen::MatrixXf out(3, static_cast<Eigen::Index>(cache.frame_count()) * sample_count);
  for (int t = 0; t < cache.frame_count(); ++t) {
    const auto frame = cache.Frame(t);
    for (int i = 0; i < sample_count; ++i) {
      out.col(static_cast<Eigen::Index>(t) * sample_count + i) =
          samples[i].Evaluate(frame).cast<float>();
    }
  }
  return out;
}

// Features of one take in float: B (DB x F) and X (DX x F*S).
struct TakeFeatures {
  Eigen::MatrixXf skull;
  Eigen::MatrixXf skin;
};

StatusOr<TakeFeatures> ComputeTakeFeatures(const Take& take, const FaceRig& rig,
                                           const FeatureConfig& config) {
  FACEDYN_ASSIGN_OR_RETURN(const Eigen::MatrixXd skull,
                           SkullDescriptors(take.world_from_skull, rig.skull_landmarks, config));
  FACEDYN_ASSIGN_OR_RETURN(const Eigen::MatrixXd skin,
                           SkinDescriptors(take, rig.skin_samples, config));
  return TakeFeatures{skull.cast<float>(), skin.cast<float>()};
}

}  // namespace

uint64_t HashSurfacePoints(const std::vector<SurfacePoint>& points) {
  uint64_t hash = 1469598103934665603ull;
  auto mix = [&hash](const void* data, size_t bytes) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (size_t k = 0; k < bytes; ++k) {
      hash ^= p[k];
      hash *= 1099511628211ull;
    }
  };
  for (const SurfacePoint& point : points) {
    for (int k = 0; k < 3; ++k) {
      const int32_t vertex = point.vertices[k];
      const double weight = point.weights[k];
      mix(&vertex, sizeof(vertex));
      mix(&weight, sizeof(weight));
    }
  }
  return hash;
}

RemovalConfig RemovalConfig::ForRig(const FaceRig& rig, double fps) {
  RemovalConfig config;
  config.features.fps = fps;
  config.landmarks = rig.skull_landmarks;
  config.sample_count = static_cast<int>(rig.skin_samples.size());
  config.samples_hash = HashSurfacePoints(rig.skin_samples);
  return config;
}

Status RemovalConfig::Check() const {
  FACEDYN_RETURN_IF_ERROR(features.Check());
  if (landmarks.empty()) return InvalidArgumentError("landmarks: at least one skull landmark");
  if (sample_count < 1) return InvalidArgumentError("sample_count must be >= 1");
  if (hidden_units < 1) return InvalidArgumentError("hidden_units must be >= 1");
  return Status::Ok();
}

struct RemovalModel::Impl {
  RemovalConfig config;
  RemovalNet net{nullptr};
};

RemovalModel::RemovalModel() = default;
RemovalModel::~RemovalModel() = default;
RemovalModel::RemovalModel(RemovalModel&&) noexcept = default;
RemovalModel& RemovalModel::operator=(RemovalModel&&) noexcept = default;

StatusOr<RemovalModel> RemovalModel::Create(const RemovalConfig& config, uint64_t seed) {
  FACEDYN_RETURN_IF_ERROR(config.Check());
  torch::manual_seed(seed);
  RemovalModel model;
  model.impl_ = std::make_unique<Impl>();
  model.impl_->config = config;
  model.impl_->net = RemovalNet(config.input_size(), config.hidden_units);
  model.impl_->net->eval();
  return model;
}

const RemovalConfig& RemovalModel::config() const {
  FACEDYN_CHECK(valid(), "config() on an empty RemovalModel");
  return impl_->config;
}

Status RemovalModel::Save(const std::string& path) const {
  FACEDYN_CHECK(valid(), "Save() on an empty RemovalModel");
  const std::string temporary = path + ".tmp";
  try {
    torch::serialize::OutputArchive archive;
    impl_->net->save(archive);
    archive.write(kConfigKey, c10::IValue(ConfigToJson(impl_->config).dump()));
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

StatusOr<RemovalModel> RemovalModel::Load(const std::string& path) {
  try {
    torch::serialize::InputArchive archive;
    archive.load_from(path);
    c10::IValue config_value;
    if (!archive.try_read(kConfigKey, config_value) || !config_value.isString()) {
      return DataLossError(path + ": no " + std::string(kConfigKey) +
                           " entry (not a facedyn removal model)");
    }
    Json json;
    try {
      json = Json::parse(config_value.toStringRef());
    } catch (const std::exception& e) {
      return DataLossError(path + ": " + kConfigKey + " is not JSON: " + e.what());
    }
    StatusOr<RemovalConfig> config = ConfigFromJson(json);
    if (!config.ok()) return config.status().WithContext(path);
    RemovalModel model;
    model.impl_ = std::make_unique<Impl>();
    model.impl_->config = *config;
    model.impl_->net = RemovalNet(config->input_size(), config->hidden_units);
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
    model.impl_->net->eval();
    return model;
  } catch (const std::exception& e) {
    return DataLossError(path + ": cannot read the model: " + e.what());
  }
}

Status RemovalModel::CheckCompatible(const Take& take, const FaceRig& rig) const {
  const RemovalConfig& config = this->config();
  const double fps = config.features.fps;
  if (!(std::abs(take.info.fps - fps) <= 1e-6 * fps)) {
    return FailedPreconditionError(
        "fps: the model was trained at " + std::to_string(fps) + " fps, the take is at " +
        std::to_string(take.info.fps) + " fps (feature windows are counted in frames)");
  }
  if (rig.skull_landmarks.size() != config.landmarks.size()) {
    return FailedPreconditionError("skull_landmarks: the model has " +
                                   std::to_string(config.landmarks.size()) +
                                   " landmarks, the rig has " +
                                   std::to_string(rig.skull_landmarks.size()));
  }
  for (size_t k = 0; k < config.landmarks.size(); ++k) {
    const Eigen::Vector3d& a = config.landmarks[k].position_in_skull;
    const Eigen::Vector3d& b = rig.skull_landmarks[k].position_in_skull;
    if ((a - b).norm() > 1e-6) {
      return FailedPreconditionError("skull_landmarks: landmark " + std::to_string(k) + " ('" +
                                     config.landmarks[k].name + "') is at " + FormatVector(a) +
                                     " mm in the model and " + FormatVector(b) +
                                     " mm in the rig");
    }
  }
  if (static_cast<int>(rig.skin_samples.size()) != config.sample_count) {
    return FailedPreconditionError("skin_samples: the model has " +
                                   std::to_string(config.sample_count) +
                                   " samples, the rig has " +
                                   std::to_string(rig.skin_samples.size()));
  }
  const uint64_t hash = HashSurfacePoints(rig.skin_samples);
  if (hash != config.samples_hash) {
    return FailedPreconditionError(
        "skin_samples: same count (" + std::to_string(config.sample_count) +
        ") but different sample definitions (hash " + Hex64(config.samples_hash) +
        " in the model, " + Hex64(hash) + " in the rig)");
  }
  return Status::Ok();
}

Eigen::MatrixXf RemovalModel::Predict(const Eigen::MatrixXf& features) const {
  const RemovalConfig& config = this->config();
  FACEDYN_CHECK(features.rows() == config.input_size(),
                "Predict: features have " + std::to_string(features.rows()) + " rows, expected " +
                    std::to_string(config.input_size()));
  Eigen::MatrixXf out(3, features.cols());
  if (features.cols() == 0) return out;
  torch::NoGradGuard no_grad;
  // Column-major (input_size x N) is row-major N x input_size: no copy.
  const torch::Tensor input = torch::from_blob(const_cast<float*>(features.data()),
                                               {features.cols(), features.rows()},
                                               torch::kFloat32);
  const torch::Tensor output = impl_->net->Forward(input).contiguous();
  std::memcpy(out.data(), output.data_ptr<float>(), sizeof(float) * out.size());
  return out;
}

void RemovalModel::SetNormalisation(const Eigen::VectorXf& input_mean,
                                    const Eigen::VectorXf& input_std,
                                    const Eigen::VectorXf& output_mean,
                                    const Eigen::VectorXf& output_std) {
  const int n = config().input_size();
  FACEDYN_CHECK(input_mean.size() == n && input_std.size() == n && output_mean.size() == 3 &&
                    output_std.size() == 3,
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

std::vector<float> RemovalModel::FlatParameters() const {
  FACEDYN_CHECK(valid(), "FlatParameters() on an empty RemovalModel");
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

Status TrainOptions::Check() const {
  if (epochs < 1) return InvalidArgumentError("epochs must be >= 1");
  if (batch_size < 1) return InvalidArgumentError("batch_size must be >= 1");
  if (!(learning_rate > 0)) return InvalidArgumentError("learning_rate must be > 0");
  if (!(validation_fraction >= 0 && validation_fraction <= 0.9)) {
    return InvalidArgumentError("validation_fraction must be in [0, 0.9]");
  }
  if (num_threads < 0) return InvalidArgumentError("num_threads must be >= 0");
  if (hidden_units < 1) return InvalidArgumentError("hidden_units must be >= 1");
  if (!(window_s > 0 && window_s <= 1)) return InvalidArgumentError("window_s must be in (0, 1]");
  return Status::Ok();
}

// Friend of RemovalModel: reaches the network for the optimisation.
struct RemovalTrainer {
  static RemovalNet& Net(RemovalModel& model) { return model.impl_->net; }
};

namespace {

// One training row: a take, a frame and a sample.
struct Row {
  int take;
  int frame;
  int sample;
};

// Training data kept per take; batches are gathered from it (a 1.5 s take at 128 fps with 344
// samples would be 100 MB of assembled float rows; B is shared by all samples of a frame).
struct TrainingData {
  int sample_count = 0;
  int skull_size = 0;
  int skin_size = 0;
  std::vector<TakeFeatures> features;
  std::vector<Eigen::MatrixXf> targets;  // 3 x F*S per take

  int input_size() const { return skull_size + skin_size; }
  Eigen::Index Column(const Row& row) const {
    return static_cast<Eigen::Index>(row.frame) * sample_count + row.sample;
  }
  // Normalised inputs (row-major rows x input) and targets (rows x 3) of rows[begin, end).
  void Gather(const std::vector<Row>& rows, size_t begin, size_t end, const Eigen::VectorXf& mean,
              const Eigen::VectorXf& inv_std, const Eigen::Vector3f& out_mean,
              const Eigen::Vector3f& out_inv_std, Eigen::MatrixXf* inputs,
              Eigen::MatrixXf* outputs) const {
    const Eigen::Index n = static_cast<Eigen::Index>(end - begin);
    inputs->resize(input_size(), n);
    outputs->resize(3, n);
    for (Eigen::Index r = 0; r < n; ++r) {
      const Row& row = rows[begin + r];
      const TakeFeatures& f = features[row.take];
      const Eigen::Index column = Column(row);
      inputs->col(r).head(skull_size) = f.skull.col(row.frame);
      inputs->col(r).tail(skin_size) = f.skin.col(column);
      inputs->col(r) = (inputs->col(r) - mean).cwiseProduct(inv_std);
      outputs->col(r) = (targets[row.take].col(column) - out_mean).cwiseProduct(out_inv_std);
    }
  }
};

torch::Tensor AsRowMajorTensor(Eigen::MatrixXf* matrix) {
  return torch::from_blob(matrix->data(), {matrix->cols(), matrix->rows()}, torch::kFloat32);
}

}  // namespace

StatusOr<RemovalModel> TrainRemoval(const std::vector<TrainingTake>& takes,
                                    const TrainOptions& options, TrainSummary* summary) {
  FACEDYN_RETURN_IF_ERROR(options.Check());
  if (takes.empty()) return InvalidArgumentError("TrainRemoval: no training takes");
  for (size_t k = 0; k < takes.size(); ++k) {
    FACEDYN_CHECK(takes[k].take != nullptr && takes[k].rig != nullptr,
                  "TrainRemoval: training take without take or rig");
  }
  if (options.num_threads > 0) torch::set_num_threads(options.num_threads);

  RemovalConfig config = RemovalConfig::ForRig(*takes[0].rig, takes[0].take->info.fps);
  config.features.window_s = options.window_s;
  config.hidden_units = options.hidden_units;
  FACEDYN_ASSIGN_OR_RETURN(RemovalModel model, RemovalModel::Create(config, options.seed));

  TrainingData data;
  data.sample_count = config.sample_count;
  data.skull_size = config.features.SkullDescriptorSize(static_cast<int>(config.landmarks.size()));
  data.skin_size = config.features.SkinDescriptorSize();
  const int window = config.features.window_frames();
  std::vector<std::pair<int, int>> frames;  // (take, frame) usable for training
  for (size_t k = 0; k < takes.size(); ++k) {
    const Take& take = *takes[k].take;
    const FaceRig& rig = *takes[k].rig;
    const std::string context = "training take " + std::to_string(k);
    Status status = model.CheckCompatible(take, rig);
    if (!status.ok()) return status.WithContext(context);
    StatusOr<TakeFeatures> features = ComputeTakeFeatures(take, rig, config.features);
    if (!features.ok()) return features.status().WithContext(context);
    data.features.push_back(std::move(features).value());
    if (options.use_exact_targets) {
      const auto channel = take.channels.find("quasistatic");
      if (channel == take.channels.end()) {
        return FailedPreconditionError(context +
                                       ": use_exact_targets but the take has no quasistatic "
                                       "channel");
      }
      StatusOr<PointCache> offsets =
          DynamicOffsets(take.positions, channel->second, take.world_from_skull);
      if (!offsets.ok()) return offsets.status().WithContext(context);
      data.targets.push_back(SampleCache(*offsets, rig.skin_samples));
    } else {
      QuasistaticOptions quasistatic;
      quasistatic.window_s = options.window_s;
      StatusOr<Take> estimate = ExtractQuasistatic(take, quasistatic);
      if (!estimate.ok()) return estimate.status().WithContext(context);
      data.targets.push_back(SampleCache(estimate->channels.at("dynamic_offset"), rig.skin_samples));
    }
    for (int t = window; t < take.frame_count() - window; ++t) {
      frames.emplace_back(static_cast<int>(k), t);
    }
  }
  if (frames.empty()) {
    return FailedPreconditionError("TrainRemoval: every take is shorter than two feature windows");
  }

  // Validation split by whole frames, seeded.
  std::mt19937_64 rng(options.seed);
  std::shuffle(frames.begin(), frames.end(), rng);
  const size_t validation_frames = static_cast<size_t>(
      std::floor(options.validation_fraction * static_cast<double>(frames.size())));
  std::vector<Row> train_rows;
  std::vector<Row> validation_rows;
  for (size_t f = 0; f < frames.size(); ++f) {
    std::vector<Row>& rows = f < validation_frames ? validation_rows : train_rows;
    for (int i = 0; i < data.sample_count; ++i) rows.push_back({frames[f].first, frames[f].second, i});
  }
  if (train_rows.empty()) return FailedPreconditionError("TrainRemoval: no training rows left");

  // Normalisation from the training rows (double accumulation).
  const int input_size = data.input_size();
  Eigen::VectorXd sum = Eigen::VectorXd::Zero(input_size);
  Eigen::VectorXd sum_sq = Eigen::VectorXd::Zero(input_size);
  Eigen::Vector3d out_sum = Eigen::Vector3d::Zero();
  Eigen::Vector3d out_sum_sq = Eigen::Vector3d::Zero();
  Eigen::VectorXd x(input_size);
  for (const Row& row : train_rows) {
    const Eigen::Index column = data.Column(row);
    x.head(data.skull_size) = data.features[row.take].skull.col(row.frame).cast<double>();
    x.tail(data.skin_size) = data.features[row.take].skin.col(column).cast<double>();
    sum += x;
    sum_sq += x.cwiseAbs2();
    const Eigen::Vector3d y = data.targets[row.take].col(column).cast<double>();
    out_sum += y;
    out_sum_sq += y.cwiseAbs2();
  }
  const double n = static_cast<double>(train_rows.size());
  auto std_of = [n](double s, double s2) {
    const double variance = std::max(0.0, s2 / n - (s / n) * (s / n));
    const double sd = std::sqrt(variance);
    return sd > 1e-9 ? sd : 1.0;  // constant dimensions pass through centred
  };
  Eigen::VectorXf mean(input_size), sd(input_size);
  for (int d = 0; d < input_size; ++d) {
    mean[d] = static_cast<float>(sum[d] / n);
    sd[d] = static_cast<float>(std_of(sum[d], sum_sq[d]));
  }
  Eigen::Vector3f out_mean, out_sd;
  for (int d = 0; d < 3; ++d) {
    out_mean[d] = static_cast<float>(out_sum[d] / n);
    out_sd[d] = static_cast<float>(std_of(out_sum[d], out_sum_sq[d]));
  }
  model.SetNormalisation(mean, sd, out_mean, out_sd);
  const Eigen::VectorXf inv_sd = sd.cwiseInverse();
  const Eigen::Vector3f out_inv_sd = out_sd.cwiseInverse();

  RemovalNet& net = RemovalTrainer::Net(model);
  net->train();
  torch::optim::Adam optimizer(net->parameters(),
                               torch::optim::AdamOptions(options.learning_rate));
  TrainSummary local;
  local.training_samples = static_cast<long>(train_rows.size());
  local.validation_samples = static_cast<long>(validation_rows.size());
  Progress progress("train-removal", options.epochs,
                    options.show_progress ? ProgressMode::kAuto : ProgressMode::kSilent);
  Eigen::MatrixXf batch_inputs, batch_targets;
  const size_t batch = static_cast<size_t>(options.batch_size);
  const auto start = std::chrono::steady_clock::now();
  for (int epoch = 0; epoch < options.epochs; ++epoch) {
    std::shuffle(train_rows.begin(), train_rows.end(), rng);
    double loss_sum = 0.0;
    for (size_t begin = 0; begin < train_rows.size(); begin += batch) {
      const size_t end = std::min(train_rows.size(), begin + batch);
      data.Gather(train_rows, begin, end, mean, inv_sd, out_mean, out_inv_sd, &batch_inputs,
                  &batch_targets);
      optimizer.zero_grad();
      const torch::Tensor loss = torch::mse_loss(
          net->ForwardNormalised(AsRowMajorTensor(&batch_inputs)), AsRowMajorTensor(&batch_targets));
      loss.backward();
      optimizer.step();
      loss_sum += loss.item<double>() * static_cast<double>(end - begin);
    }
    local.train_loss.push_back(loss_sum / n);
    char status[96];
    if (!validation_rows.empty()) {
      torch::NoGradGuard no_grad;
      double validation_sum = 0.0;
      for (size_t begin = 0; begin < validation_rows.size(); begin += batch) {
        const size_t end = std::min(validation_rows.size(), begin + batch);
        data.Gather(validation_rows, begin, end, mean, inv_sd, out_mean, out_inv_sd,
                    &batch_inputs, &batch_targets);
        validation_sum += torch::mse_loss(net->ForwardNormalised(AsRowMajorTensor(&batch_inputs)),
                                          AsRowMajorTensor(&batch_targets))
                              .item<double>() *
                          static_cast<double>(end - begin);
      }
      local.validation_loss.push_back(validation_sum /
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
  local.train_s = SecondsSince(start);
  local.samples_per_s =
      local.train_s > 0 ? static_cast<double>(options.epochs) * n / local.train_s : 0.0;
  if (summary != nullptr) *summary = std::move(local);
  return model;
}

SamplePropagation BuildSamplePropagation(const FaceRig& rig, int k) {
  const Eigen::Matrix3Xd samples = rig.SamplePositions(rig.neutral.positions_mm);
  const int sample_count = static_cast<int>(samples.cols());
  FACEDYN_CHECK(sample_count >= 1 && k >= 1, "BuildSamplePropagation: no samples or k < 1");
  k = std::min(k, sample_count);
  // sigma: mean distance from a sample to its nearest other sample.
  double spacing_sum = 0.0;
  for (int i = 0; i < sample_count; ++i) {
    double nearest = std::numeric_limits<double>::infinity();
    for (int j = 0; j < sample_count; ++j) {
      if (j != i) nearest = std::min(nearest, (samples.col(i) - samples.col(j)).squaredNorm());
    }
    spacing_sum += sample_count > 1 ? std::sqrt(nearest) : 10.0;
  }
  const double sigma = std::max(1e-3, spacing_sum / sample_count);
  const double inv_two_sigma_sq = 1.0 / (2.0 * sigma * sigma);

  SamplePropagation propagation;
  propagation.k = k;
  const int vertex_count = rig.vertex_count();
  propagation.sample_index.resize(static_cast<size_t>(vertex_count) * k);
  propagation.weight.resize(static_cast<size_t>(vertex_count) * k);
  std::vector<double> d2(sample_count);
  std::vector<int> order(sample_count);
  for (int v = 0; v < vertex_count; ++v) {
    for (int i = 0; i < sample_count; ++i) {
      d2[i] = (samples.col(i) - rig.neutral.positions_mm.col(v)).squaredNorm();
    }
    std::iota(order.begin(), order.end(), 0);
    std::partial_sort(order.begin(), order.begin() + k, order.end(),
                      [&d2](int a, int b) { return d2[a] < d2[b] || (d2[a] == d2[b] && a < b); });
    double total = 0.0;
    std::vector<double> w(k);
    for (int j = 0; j < k; ++j) {
      w[j] = std::exp(-(d2[order[j]] - d2[order[0]]) * inv_two_sigma_sq);
      total += w[j];
    }
    for (int j = 0; j < k; ++j) {
      propagation.sample_index[static_cast<size_t>(v) * k + j] = order[j];
      propagation.weight[static_cast<size_t>(v) * k + j] = static_cast<float>(w[j] / total);
    }
  }
  return propagation;
}

StatusOr<Take> RemoveDynamics(const RemovalModel& model, const Take& take, const FaceRig& rig,
                              RemovalSummary* summary) {
  FACEDYN_RETURN_IF_ERROR(model.CheckCompatible(take, rig));
  if (rig.vertex_count() != take.vertex_count()) {
    return FailedPreconditionError("vertex_count: the rig has " +
                                   std::to_string(rig.vertex_count()) + " vertices, the take " +
                                   std::to_string(take.vertex_count()));
  }
  const auto start = std::chrono::steady_clock::now();
  const RemovalConfig& config = model.config();
  FACEDYN_ASSIGN_OR_RETURN(const TakeFeatures features,
                           ComputeTakeFeatures(take, rig, config.features));
  const int frame_count = take.frame_count();
  const int sample_count = config.sample_count;
  const int skull_size = static_cast<int>(features.skull.rows());
  const int skin_size = static_cast<int>(features.skin.rows());
  // dx of every sample and frame: 3 x F*S, column t * S + i. Batches of whole frames.
  Eigen::MatrixXf sample_offsets(3, static_cast<Eigen::Index>(frame_count) * sample_count);
  const int chunk_frames = std::max(1, 16384 / sample_count);
  Eigen::MatrixXf inputs;
  for (int t0 = 0; t0 < frame_count; t0 += chunk_frames) {
    const int t1 = std::min(frame_count, t0 + chunk_frames);
    inputs.resize(skull_size + skin_size, static_cast<Eigen::Index>(t1 - t0) * sample_count);
    for (int t = t0; t < t1; ++t) {
      for (int i = 0; i < sample_count; ++i) {
        const Eigen::Index column = static_cast<Eigen::Index>(t - t0) * sample_count + i;
        inputs.col(column).head(skull_size) = features.skull.col(t);
        inputs.col(column).tail(skin_size) =
            features.skin.col(static_cast<Eigen::Index>(t) * sample_count + i);
      }
    }
    sample_offsets.middleCols(static_cast<Eigen::Index>(t0) * sample_count, inputs.cols()) =
        model.Predict(inputs);
  }
  const double predict_s = SecondsSince(start);

  const auto propagate_start = std::chrono::steady_clock::now();
  const SamplePropagation propagation = BuildSamplePropagation(rig);
  Take result;
  result.info = take.info;
  result.info.source = "dynamics remove";
  result.info.metadata["removal_sample_count"] = sample_count;
  result.info.metadata["removal_window_frames"] = config.features.window_frames();
  result.info.metadata["removal_propagation"] = "gaussian_knn";
  result.topology = take.topology;
  result.time_s = take.time_s;
  result.world_from_skull = take.world_from_skull;
  result.skull_from_jaw = take.skull_from_jaw;
  result.positions = take.positions;
  PointCache offsets = take.positions;
  const int vertex_count = take.vertex_count();
  const int k = propagation.k;
  for (int t = 0; t < frame_count; ++t) {
    const auto dx = sample_offsets.middleCols(static_cast<Eigen::Index>(t) * sample_count,
                                              sample_count);
    Eigen::Map<Eigen::Matrix3Xf> offset = offsets.Frame(t);
    for (int v = 0; v < vertex_count; ++v) {
      Eigen::Vector3f sum = Eigen::Vector3f::Zero();
      const size_t base = static_cast<size_t>(v) * k;
      for (int j = 0; j < k; ++j) {
        sum += propagation.weight[base + j] * dx.col(propagation.sample_index[base + j]);
      }
      offset.col(v) = sum;
    }
    const Eigen::Matrix3f world_from_skull_rotation =
        take.world_from_skull[t].RotationMatrix().cast<float>();
    result.positions.Frame(t) -= world_from_skull_rotation * offset;
  }
  result.channels["dynamic_offset"] = std::move(offsets);
  const double propagate_s = SecondsSince(propagate_start);
  if (summary != nullptr) {
    summary->predict_s = predict_s;
    summary->propagate_s = propagate_s;
    const double total = predict_s + propagate_s;
    summary->frames_per_s = total > 0 ? frame_count / total : 0.0;
  }
  return result;
}

}  // namespace facedyn::dynamics
