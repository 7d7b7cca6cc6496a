#pragma once
// Segmentation classes of an occupancy grid's cells from a classified point layer
// (PointLayer::classes, point_map.hpp): each cell takes the most frequent class of the points
// that fall in it (a 2D grid: in its column, any height; a 3D grid: in the cell), ties to the
// lower index; cells without a classified point get msgs::kNoClass.
//
// Frames and units: the grid's origin pose places cell (0, 0, 0)'s corner in the points' world
// frame; metres.

#include "hanzo/fusion/msgs/map_messages.hpp"

namespace hanzo::fusion::maps {

/// Fills grid.classes (one per cell, replacing any there); leaves it empty when the points
/// have no classes.
void classify_cells(msgs::OccupancyGridLayer& grid, const msgs::PointLayer& points);

}  // namespace hanzo::fusion::maps
