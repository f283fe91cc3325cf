// From image files to a CalibrationInput: glob expansion, grouping into cameras and views, and
// board detection, with every unusable image reported (not fatal) by name and reason.
//
// Grouping: with CameraGrouping::kByDirectory each parent folder is a camera (named after the
// folder) and images with the same file name stem in different folders are the same view (the
// same instant), which is how a capture session or a multi-camera calibration shoot lays them
// out (cam0/0001.png, cam1/0001.png, ...). kSingleCamera makes every image a view of one
// camera. kAuto picks kByDirectory when the images span more than one folder.
#pragma once

#include <string>
#include <vector>

#include "core/status.h"
#include "reconstruct/board.h"
#include "reconstruct/calibration.h"

namespace facedyn::reconstruct {

enum class CameraGrouping { kAuto, kByDirectory, kSingleCamera };

// Expands each pattern with glob(3) (a pattern without wildcards must name an existing file),
// sorted, without duplicates. NotFound naming the pattern when one matches nothing.
StatusOr<std::vector<std::string>> ExpandImagePatterns(const std::vector<std::string>& patterns);

struct SkippedImage {
  std::string path;
  std::string reason;
};

// Reads every image (grayscale), detects the board and groups the observations. Unreadable
// images and images without the board are listed in *skipped; images of one camera with
// different sizes are an error naming both.
StatusOr<CalibrationInput> DetectBoardInImages(const std::vector<std::string>& paths,
                                               const BoardSpec& board, CameraGrouping grouping,
                                               std::vector<SkippedImage>* skipped);

}  // namespace facedyn::reconstruct
