#include "fmv3d/sfm/focal_decision.h"

namespace fmv3d::sfm {

const char* FocalDecisionName(FocalDecisionKind kind) {
  switch (kind) {
    case FocalDecisionKind::kKnown:
      return "known";
    case FocalDecisionKind::kDistorted:
      return "distorted";
    case FocalDecisionKind::kUndetermined:
      return "undetermined";
    case FocalDecisionKind::kPlateau:
      return "plateau";
    case FocalDecisionKind::kMinimum:
      return "minimum";
    case FocalDecisionKind::kRestart:
      return "restart";
    case FocalDecisionKind::kNone:
      break;
  }
  return "none";
}

}  // namespace fmv3d::sfm
