// The models the repository ships in models/ (the compact ICT-FaceKit head
// model and its general avatar model, the built-in head's general model), found
// without the user naming a path: they sit beside the programs in a build or
// an installation.
#pragma once

#include <string>
#include <vector>

namespace headcast {

// The folders searched, in order: $HEADCAST_MODELS; the installation's
// share/headcast/models (PREFIX/bin/../share/...); the source tree's models/
// above a build folder (BUILD/bin/../../models).
std::vector<std::string> ShippedModelFolders();

// The path of `name` (e.g. "ict_facekit.npz") in the first folder that has it.
// Throws std::runtime_error listing where it looked, and how to make it.
std::string ShippedModelPath(const std::string& name);

// How to call another headcast program in a command printed for the user:
// its bare name when it sits in a folder on the usual PATH (an installation),
// else its full path beside this program (a build folder).
std::string SiblingProgram(const std::string& name);

}  // namespace headcast
