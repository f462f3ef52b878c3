#pragma once
// Surface sources of a PPF model (docs/model-file.md): a mesh (PLY, STL) sampled into oriented
// points, or a reference scan (PLY, PCD) with its normals read or estimated. Both feed
// match::model_from_samples; coordinates are taken as the part frame, in mm. The files are read
// by PCL's io (PLY, PCD) and VTK (STL); their failures come back as errors naming the file.
#include <Eigen/Core>
#include <filesystem>
#include <vector>

#include "hotgauge/core/result.hpp"

namespace hotgauge::model {

struct SurfaceSamples {
    std::vector<Eigen::Vector3f> points;   // mm
    std::vector<Eigen::Vector3f> normals;  // unit, one per point
};

// Samples the triangles of a mesh uniformly by area (fixed seed: the same file gives the same
// samples), about one sample per spacing_mm² of surface, each with its triangle's normal
// (right-hand winding: counter-clockwise seen from outside is outward).
// PLY (pcl::PLYReader): ascii, binary little- or big-endian; vertex x, y, z of any number type;
// face list vertex_indices (or vertex_index) with a uchar or uint count, polygons
// fan-triangulated; an index out of range or a non-finite vertex in a face is an error.
// STL (vtkSTLReader): ascii or binary; a binary file shorter than its triangle count is an error.
// Degenerate triangles are skipped; a file without a usable triangle is an error.
core::Result<SurfaceSamples> read_mesh_samples(const std::filesystem::path& path,
                                               double spacing_mm);

// The points of a scan. PLY (pcl::PLYReader, any encoding: vertex x, y, z, optional nx, ny, nz)
// or PCD (pcl::PCDReader: ascii, binary or binary_compressed; fields x y z, optional normal_x
// normal_y normal_z; other fields skipped). Points with a non-finite coordinate or normal are
// dropped. Without normals in the file, they are estimated by match::estimate_normals (PCA of
// the 12 nearest neighbours, oriented towards +z: the sensor looks down the scan's −z; on walls
// parallel to z that orientation is arbitrary).
core::Result<SurfaceSamples> read_scan_samples(const std::filesystem::path& path);

}  // namespace hotgauge::model
