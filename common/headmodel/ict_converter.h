// Converts ICT-FaceKit's upstream folder (MIT licence) into a HeadModel.
#pragma once

#include <string>
#include <vector>

#include "common/headmodel/head_model.h"

namespace headcast {

// Parts of the ICT mesh by vertex range (0-based, inclusive), as upstream documents them.
struct IctPart {
  const char* name;
  int first, last;
};
const std::vector<IctPart>& IctParts();  // face, head, mouth, eyes, gums_tongue, teeth, eyeballs, eye_accessories

// What a conversion keeps unless told otherwise: every part but
// `eye_accessories`. Those are the occlusion shells and lashes that sit in front
// of the eyeballs; upstream draws them translucent, but the avatar's rasteriser
// draws every triangle opaque, so with them the eye opening shows a flat
// membrane that follows the lids instead of the eyeball that follows the gaze.
std::vector<std::string> IctDefaultParts();

struct IctConvertOptions {
  std::string folder;                                  // the FaceXModel folder (or its parent)
  int max_identity = 100;                              // identity components to read (identity000.obj ...)
  std::vector<std::string> parts = IctDefaultParts();  // names from IctParts(); empty: every part
  // Upstream has no albedo, so every render of the model (a general model's
  // synthetic training pictures, the fit panel) is one skin colour: skin-lit
  // mouth cavities and blank eyeballs. Painted, each part has a plain colour
  // of its own (IctPartAlbedo) and the eyeballs a sclera, iris and pupil about
  // their front pole. On: the shipped general model is continued on painted
  // renders, and a fine-tune mixes renders of the model it is given.
  bool paint_parts = true;
  void Check() const;
};

// The plain colour (linear RGB in [0, 1]) a painted conversion gives a part;
// the eyeballs' is their sclera.
Eigen::Vector3f IctPartAlbedo(const std::string& part);
// An eyeball's colour at an angle (radians) from its front pole: pupil, iris,
// a darker limbal ring, sclera.
Eigen::Vector3f IctEyeballAlbedo(double angle);

// Reads generic_neutral_mesh.obj, the expression OBJs listed in
// vertex_indices.json and identityNNN.obj; converts centimetres to metres;
// quads are split into triangles. The jaw is a blendshape; each eyeball is
// skinned to its eye joint (gaze), everything else to the root. Throws naming the file.
HeadModel ConvertIctFaceKit(const IctConvertOptions& options);

// The 68 iBUG landmark vertex ids of the full ICT mesh.
const std::vector<int>& IctLandmarkVertices();

}  // namespace headcast
