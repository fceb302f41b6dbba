// Chessboard views from a calibration video: `fmv3d calibrate` and the console's calibration window accept videos
// among their inputs. Frames are sampled evenly over the video, the board is detected in each sample, and among
// the views where it was found a subset spread over the image and over the board's apparent pose is kept: a video
// holds long runs of nearly equal views, which would weigh one pose many times and cost time without adding
// information. The spread is greedy farthest-point sampling on the board's four outer corners (in a canonical
// order, so that a board seen upside down is not a new pose) in image-normalised coordinates, starting from the
// view where the board looks largest.
// A sampled frame is named like a frame of `fmv3d frames`: "<video stem>-<frame index, 6 digits>.png", the index
// counted from 0 in the decoder's output order.
#pragma once

#include <filesystem>
#include <opencv2/core.hpp>
#include <set>
#include <string>
#include <vector>

#include "fmv3d/calib/chessboard.h"

namespace fmv3d::calib {

struct VideoBoardOptions {
  int samples = 60;    // frames sampled evenly over the video
  int max_views = 20;  // views kept among those where the board was found
  void Check() const;
};

struct VideoBoardViews {
  std::vector<BoardDetection> detections;  // the kept views, in frame order
  std::vector<cv::Mat> images;             // parallel: the frames (8-bit BGR)
  int sampled = 0, found = 0;              // frames sampled; of those, with the board found (and not excluded)
  std::vector<std::string> excluded;       // sampled frames named in `exclude`
};

// Throws fmv3d::Error naming the file when it is not a readable video or yields no frame.
VideoBoardViews DetectBoardsInVideo(const std::filesystem::path& video, const BoardSpec& board,
                                    const VideoBoardOptions& options, const std::set<std::string>& exclude = {});

// Indices (ascending) of at most max_views detections (found ones only) spread as described above.
std::vector<size_t> ChooseSpreadViews(const std::vector<BoardDetection>& views, const BoardSpec& board,
                                      size_t max_views);

}  // namespace fmv3d::calib
