#include "reconstruct/calibration_images.h"

#include <glob.h>

#include <algorithm>
#include <filesystem>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <set>

#include "core/progress.h"

namespace facedyn::reconstruct {

StatusOr<std::vector<std::string>> ExpandImagePatterns(const std::vector<std::string>& patterns) {
  std::set<std::string> paths;
  for (const std::string& pattern : patterns) {
    if (pattern.find_first_of("*?[") == std::string::npos) {
      if (!std::filesystem::is_regular_file(pattern)) {
        return NotFoundError("image " + pattern + " does not exist");
      }
      paths.insert(pattern);
      continue;
    }
    glob_t matches{};
    const int rc = glob(pattern.c_str(), 0, nullptr, &matches);
    if (rc != 0 || matches.gl_pathc == 0) {
      globfree(&matches);
      return NotFoundError("no image matches " + pattern);
    }
    for (size_t i = 0; i < matches.gl_pathc; ++i) {
      if (std::filesystem::is_regular_file(matches.gl_pathv[i])) paths.insert(matches.gl_pathv[i]);
    }
    globfree(&matches);
  }
  return std::vector<std::string>(paths.begin(), paths.end());
}

StatusOr<CalibrationInput> DetectBoardInImages(const std::vector<std::string>& paths,
                                               const BoardSpec& board, CameraGrouping grouping,
                                               std::vector<SkippedImage>* skipped) {
  if (paths.empty()) return InvalidArgumentError("no calibration images given");
  std::set<std::string> folders;
  for (const std::string& path : paths) {
    folders.insert(std::filesystem::path(path).parent_path().lexically_normal().string());
  }
  const bool by_directory = grouping == CameraGrouping::kByDirectory ||
                            (grouping == CameraGrouping::kAuto && folders.size() > 1);
  CalibrationInput input;
  input.board = board;
  std::map<std::string, int> camera_index, view_index;
  std::map<int, std::string> first_image_of_camera;
  Progress progress("calibrate: detect", static_cast<long>(paths.size()));
  for (const std::string& path : paths) {
    progress.Advance();
    const std::filesystem::path p(path);
    // The folder names the camera (for one camera: the folder of the first image).
    std::string camera_name = (by_directory ? p : std::filesystem::path(paths.front()))
                                  .parent_path()
                                  .lexically_normal()
                                  .filename()
                                  .string();
    if (camera_name.empty() || camera_name == "." || camera_name == "..") camera_name = "camera";
    const std::string view_name = by_directory ? p.stem().string() : p.filename().string();
    const cv::Mat gray = cv::imread(path, cv::IMREAD_GRAYSCALE);
    if (gray.empty()) {
      if (skipped)
        skipped->push_back({path, "cannot be read as an image (corrupt or unsupported)"});
      continue;
    }
    auto [camera_it, new_camera] =
        camera_index.emplace(camera_name, static_cast<int>(input.cameras.size()));
    if (new_camera) {
      input.cameras.push_back({camera_name, gray.cols, gray.rows});
      first_image_of_camera[camera_it->second] = path;
    }
    const auto& camera = input.cameras[camera_it->second];
    if (camera.width_px != gray.cols || camera.height_px != gray.rows) {
      return FailedPreconditionError(
          "images of camera " + camera_name +
          " differ in size: " + first_image_of_camera[camera_it->second] + " is " +
          std::to_string(camera.width_px) + "x" + std::to_string(camera.height_px) + ", " + path +
          " is " + std::to_string(gray.cols) + "x" + std::to_string(gray.rows));
    }
    const auto corners = DetectBoard(gray, board);
    if (!corners.ok()) {
      if (skipped) skipped->push_back({path, corners.status().message()});
      continue;
    }
    auto [view_it, new_view] =
        view_index.emplace(view_name, static_cast<int>(input.view_names.size()));
    if (new_view) input.view_names.push_back(view_name);
    input.observations.push_back({camera_it->second, view_it->second, *corners});
  }
  progress.Finish();
  if (input.observations.empty()) {
    std::string reasons;
    for (size_t i = 0; skipped && i < skipped->size() && i < 3; ++i) {
      reasons += (i ? "; " : ": ") + (*skipped)[i].path + ": " + (*skipped)[i].reason;
    }
    return NotFoundError("the board " + board.ToString() + " was found in none of the " +
                         std::to_string(paths.size()) + " images" + reasons);
  }
  return input;
}

}  // namespace facedyn::reconstruct
