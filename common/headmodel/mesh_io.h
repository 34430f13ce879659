// Triangle meshes from and to OBJ/PLY files, their sanity checks, and two
// remeshing helpers (midpoint subdivision, vertex-clustering decimation) that
// make different-topology copies of a model mesh for tests and benchmarks.
#pragma once

#include <array>
#include <string>

#include "common/headmodel/head_model.h"

namespace headcast {

struct TriangleMesh {
  RowMatrixX3f vertices;  // N x 3
  RowMatrixX3i faces;     // F x 3 (polygons are fanned into triangles on reading)
};

// Reads Wavefront OBJ (v/f records; texture and normal indices ignored;
// negative indices allowed) or PLY (ascii, binary_little_endian or
// binary_big_endian; "vertex" x,y,z and "face" vertex_indices/vertex_index).
// Throws std::runtime_error naming the file and line/element on anything
// malformed: unknown format, truncated data, index out of range, NaN or
// infinite coordinates, an empty mesh.
TriangleMesh ReadMesh(const std::string& path);
// Writes OBJ or PLY (ascii) by extension.
void WriteMesh(const std::string& path, const TriangleMesh& mesh);

struct MeshDiagnostics {
  int non_manifold_edges = 0;  // edges shared by more than two faces
  int degenerate_faces = 0;    // repeated vertex index or zero area
  int unreferenced_vertices = 0;
  int non_finite_vertices = 0;
  double bounding_diagonal = 0;  // of the referenced vertices, in the mesh's units
  double rms_radius = 0;         // RMS distance of the vertices from their centroid
};
MeshDiagnostics Diagnose(const TriangleMesh& mesh);

// Every triangle split into four at its edge midpoints (shared midpoints are
// shared vertices): a denser mesh on exactly the same surface.
TriangleMesh SubdivideMidpoints(const TriangleMesh& mesh);
// Vertices merged per cube of side `cell` (their mean), faces re-indexed,
// collapsed faces removed and faces that would make an edge non-manifold
// dropped: a coarser mesh close to the original surface.
TriangleMesh ClusterDecimate(const TriangleMesh& mesh, double cell);

}  // namespace headcast
