// HeadFitter: fits the head model to one frame's 68 detected landmarks with
// Ceres — cam_from_head, expression and jaw, warm-started from the previous
// frame, with priors (METHOD §2, landmark term and regularisers). Identity
// (shape, focal length) is calibrated separately over key frames, then frozen.
#pragma once

#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

#include "common/core/camera.h"
#include "common/headmodel/head_model.h"
#include "common/headmodel/params.h"

namespace ceres {
class Problem;
}

namespace headcast {

struct EyeIrises;  // iris_locator.h

// Points of the head that no expression moves (skull, hairline), head frame,
// and where optical flow found them in this frame.
struct RigidObservations {
  std::vector<Eigen::Vector3d> head;      // metres
  std::vector<Eigen::Vector2d> observed;  // pixels
  // Per point its weight against a landmark; empty: every point
  // HeadFitterOptions::rigid_flow_weight.
  std::vector<double> weight;
  // Appends `more`, their weights (or `more_weight` for each when it has none).
  void Append(const RigidObservations& more, double own_weight, double more_weight);
};

// The values of HeadFitterOptions::eye_look_prior_shapes.
inline const std::vector<std::string> kEyeLookPriorShapes = {"all", "vertical"};

struct HeadFitterOptions {
  int num_expression = 0;  // expression components fitted (0: all the model has)
  // Weight of sum(psi^2) against squared pixels. Strong enough that a
  // coefficient moves only for what the landmarks show: weaker, a frame's
  // landmark noise is spread over dozens of shapes at their bounds (a shut eye
  // fitted as a "wide" one looking down), and the avatar learns those codes.
  double expression_prior = 5;
  // Each fitted expression coefficient is clamped to +-this, inside the
  // stream's limit (FrameParams::IsValid refuses |psi| > 5): beyond it a fit is
  // chasing landmark noise. (Tighter clamps cost landmark accuracy on talking_d9.)
  double expression_limit = 4.5;
  // Weight of the squared distance of each coefficient outside the model's
  // natural range (HeadModelData::expression_min/max; ICT: 0..1), against
  // squared pixels. Without it ICT fits chase landmarks with eye-look and jaw
  // blendshapes at -4..+4, which no avatar can be conditioned on.
  double expression_range_weight = 100;
  // Added to expression_prior for the coefficients that stand for lid motion
  // with gaze (ICT's eyeLook*). Those shapes move only the lids (the eyes
  // turn by joint), so a fit can close a lid by "looking down"; the avatar is
  // then conditioned on one code for lowered eyes and for shut ones. Weighted,
  // the fit closes lids with the blink shapes and gaze stays with the joints.
  double eye_look_prior = 0;
  // Which eyeLook shapes the prior weighs: "all" eight, or "vertical" (Up and
  // Down) only — the lid confusion is vertical, while In and Out move the lids
  // with a sideways look that the avatar's eyes should follow.
  std::string eye_look_prior_shapes = "all";  // one of kEyeLookPriorShapes
  // Weight of each vertical eyeLook coefficient against the lid motion the
  // eye's own pitch implies, against squared pixels; 0: off. The upper lid
  // follows a vertical look (it rides on the eyeball), so how far eyeLookUp or
  // eyeLookDown moves the lids is decided by the gaze the irises show, and what
  // else the lid landmarks show has to be a blink or a wide eye — where a prior
  // toward zero (eye_look_prior) also takes away the lids of a real look.
  double lid_gaze_weight = 0;
  double jaw_prior = 10;        // weight of |jaw|^2 (radians^2)
  double contour_weight = 0.5;  // landmarks 0..16 sit on a contour the model only approximates
  int max_iterations = 25;      // Levenberg-Marquardt iterations per frame
  double huber_px = 3;          // robust loss scale on landmark residuals, pixels
  // Gaze (the eye joints), fitted to located irises when the model's eyes are articulated.
  double iris_weight = 1;        // an iris against a landmark
  double gaze_prior = 10;        // weight of the eyes' pitch and yaw^2 (radians^2) against squared pixels
  double vergence_weight = 50;   // weight of |left - right|^2: the eyes look together, which steadies one-eye noise
  double eye_roll_weight = 1e4;  // an eye does not roll about its line of sight (unobservable from the iris)
  double max_gaze_rad = 0.7;     // an eye turns about 45 degrees at most; a larger fit is a wrong iris
  // Rigid points followed by optical flow from the previous frame (forehead,
  // hairline: head vertices no expression moves), each weighted against a
  // landmark; 0: off. Landmarks alone trade the head's position for
  // expression: on an expressive face the fitted head slides against the
  // hair, and the avatar's outline with it.
  double rigid_flow_weight = 0;
  double shape_prior = 1e-2;    // calibration: weight of sum(beta^2) against squared pixels per landmark
  double max_focal_change = 2;  // calibration: the focal length stays within this factor of the initial one
  // Calibration: weight of |the key frames' mean expression|^2, per key frame,
  // against squared pixels. Per frame an expression is far cheaper than a
  // shape (expression_prior against shape_prior), so what is the same in every
  // key frame can be fitted as an expression held in every frame instead of
  // the identity, and that expression then cannot move further when the face
  // does (an eye opening at its bound). Off by default: what the shape can take
  // over depends on the model's shape space (see the benchmark report).
  double calibration_mean_expression = 0;
  void Check() const;
};

struct LandmarkFitResult {
  bool ok = false;
  double rms_px = 0;  // landmark reprojection error after the fit, pixels
  int iterations = 0;
};

class HeadFitter {
 public:
  HeadFitter(const HeadModel& model, const HeadFitterOptions& options = {});
  // Identity used from now on (shape beta; zero when never set).
  void SetIdentity(const Eigen::VectorXd& shape);
  // Fits `frame` (expression, jaw, cam_from_head) to `landmarks`, starting from
  // its current values. A frame whose cam_translation.z <= 0 is initialised
  // from the landmarks (PnP on a neutral face) first. With `irises`, the eye
  // joints (left_eye, right_eye) are fitted too when the model's eyes move and
  // an iris was found; otherwise the frame keeps its gaze (held through blinks).
  // With `rigid`, those points hold the pose too (rigid_flow_weight).
  LandmarkFitResult Fit(const Landmarks2d& landmarks, const PinholeCamera& camera, FrameParams* frame,
                        const EyeIrises* irises = nullptr, const RigidObservations* rigid = nullptr) const;
  // The rigid points `frame` shows facing the camera: head frame and where they project.
  void RigidPointsInView(const FrameParams& frame, const PinholeCamera& camera, std::vector<Eigen::Vector3d>* head,
                         std::vector<Eigen::Vector2d>* pixels) const;
  // Head-frame points projected with `frame`'s pose.
  void ProjectRigidPoints(const FrameParams& frame, const PinholeCamera& camera,
                          const std::vector<Eigen::Vector3d>& head, std::vector<Eigen::Vector2d>* pixels) const;
  // Where the model's pupils project for `frame` (left, right); false when the model has no eyes to turn.
  bool ProjectPupils(const FrameParams& frame, const PinholeCamera& camera, Eigen::Vector2d* left,
                     Eigen::Vector2d* right) const;
  // Identity calibration over key frames of one person and one fixed camera
  // (METHOD §2): shape and focal length shared by all frames, pose,
  // expression and jaw per frame, starting from per-frame fits with the
  // current identity. Key frames should span head turns (the focal length is
  // only observable through perspective changes). On success the identity is
  // set, *frames holds the frames' parameters and the calibrated camera is returned.
  // With `known_focal` (the user gave the intrinsics) the focal length stays
  // that of `initial`: it is a measurement, not a starting value.
  struct Calibration {
    bool ok = false;
    Eigen::VectorXd shape;
    PinholeCamera camera;
    double rms_px = 0;
    int frames = 0;
  };
  Calibration CalibrateIdentity(const std::vector<Landmarks2d>& key_frames, const PinholeCamera& initial,
                                std::vector<FrameParams>* frames = nullptr, bool known_focal = false);
  // Model landmarks of `frame` projected with `camera`.
  Landmarks2d Project(const FrameParams& frame, const PinholeCamera& camera) const;
  const HeadFitterOptions& options() const { return options_; }

 private:
  struct LandmarkBasis;
  // For the current identity; or, with `shape_free`, for the template with the
  // shape directions too (identity calibration, where shape is an unknown).
  LandmarkBasis MakeBasis(const PoseVector& pose, bool shape_free = false) const;
  // The expression regulariser and, for models with a natural range, the soft box.
  void AddExpressionPriors(ceres::Problem* problem, double* expression) const;
  // The pupil residuals and gaze priors; false when no iris was usable.
  bool AddGaze(ceres::Problem* problem, const EyeIrises& irises, const PinholeCamera& camera, double* rotation,
               double* translation, double* left_eye, double* right_eye) const;
  // Adds the lid_gaze_weight residuals; the eye blocks stay constant unless `gaze_fitted`.
  void AddLidGaze(ceres::Problem* problem, double* expression, double* left_eye, double* right_eye,
                  bool gaze_fitted) const;
  const HeadModel& model_;
  HeadFitterOptions options_;
  HeadIdentity identity_;
  int num_expression_;
  std::vector<double> expression_prior_weights_;  // per fitted coefficient: sqrt of its prior (eyeLook* heavier)
  // The vertical eyeLook coefficients and what ties each to its eye's pitch (lid_gaze_weight).
  struct LidGaze {
    int coefficient;
    int joint;             // kLeftEyeJoint or kRightEyeJoint: the side the shape moves
    double sign;           // +1: the shape is a look up, -1: down
    double radians;        // the look whose lids the shape at 1 draws
    Eigen::Vector3d axis;  // the eye's line of sight at rest (pivot to pupil), head frame
  };
  std::vector<LidGaze> lid_gaze_;
  std::vector<int> rigid_vertices_;  // above the brows, moved by no expression
  RowMatrixX3f rigid_normals_;       // theirs, for the identity
};

// The normalised landmark error: mean distance / outer-eye-corner distance (points 36, 45).
double LandmarkErrorIod(const Landmarks2d& a, const Landmarks2d& b);
// Jitter at the middle of three consecutive frames' landmarks: the mean second
// difference of each point over the middle frame's outer-eye-corner distance.
double LandmarkJitterIod(const Landmarks2d& before, const Landmarks2d& at, const Landmarks2d& after);

}  // namespace headcast
