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

bool FocalMayRestart(FocalDecisionKind kind) {
  return kind == FocalDecisionKind::kMinimum || kind == FocalDecisionKind::kUndetermined ||
         kind == FocalDecisionKind::kPlateau;
}

}  // namespace fmv3d::sfm
