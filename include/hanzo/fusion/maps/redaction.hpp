#pragma once
// Map redaction before a map leaves the organization (spec, Security: "removes semantic labels
// and reduces geometric resolution to prevent detailed facility reconstruction").
//
// Per layer, with r = RedactionConfig::resolution:
//  - points: voxelized at r (one centroid per voxel, mean intensity, position_std at least
//    r / sqrt(12), the most frequent geometric label and segmentation class of the points
//    merged, the class's probability their mean);
//  - occupancy: cells merged k x k (x k) with k = round(r / resolution) >= 1; a merged cell
//    takes the highest probability of its observed cells (an obstacle never disappears by
//    redaction) and is unknown when none was observed; cell labels and classes do not survive
//    merging (k > 1);
//  - mesh: vertex clustering at r (vertices in one voxel merge into their centroid; triangles
//    that collapse are dropped; vertex labels do not survive the clustering);
//  - TSDF: removed (a coarse TSDF would still describe the surfaces at the original
//    resolution through its distances); the report says so;
//  - Gaussian splats and the neural field: removed whenever r > 0 (they render the facility
//    photorealistically from any viewpoint).
// Labels are removed from every layer when drop_labels is set; the sensor configuration and
// the provenance's input log paths when drop_sensor_details is set. The redaction itself is
// recorded in the provenance parameters. The result keeps the map id and the version it was made
// from: saved to a map store it becomes the next version, with that one as its parent.

#include <string>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"

namespace hanzo::fusion::maps {

struct RedactionConfig {
  bool drop_labels = true;
  /// Coarsest geometry kept (m); 0 keeps the resolution.
  double resolution = 0.5;
  bool drop_sensor_details = false;
};

struct RedactionReport {
  std::vector<std::string> actions;  ///< one line per change made, for the CLI and logs
};

/// Fails when the configuration is invalid (negative or non-finite resolution).
Result<msgs::FusionMap> redact_map(const msgs::FusionMap& map, const RedactionConfig& config, RedactionReport* report = nullptr);

}  // namespace hanzo::fusion::maps
