// AvatarConfig: every size and switch of the CNeRF avatar backend in one checked struct.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "common/avatar/avatar_backend.h"
#include "common/avatar/matte.h"
#include "common/headmodel/head_outline.h"

namespace headcast {

enum class SamplingMode {
  kMeshGuided,  // samples in a shell around the rasterised head; rays that miss are skipped
  kUniform,     // NeRF/HeadNeRF style: every ray, samples spread over a depth range
};

// How the avatar's outline is drawn.
enum class MatteMode {
  kNone,     // the renderer's RGB is the picture, background included (the thesis's avatar)
  kLearned,  // the renderer also predicts coverage at full resolution; RGB is composited over the background
  kBounded,  // kLearned, with the coverage kept inside the region the training masks may cover (MatteBound)
};
const char* MatteModeName(MatteMode mode);
MatteMode ParseMatteMode(const std::string& name);  // throws std::invalid_argument naming the choices

// What of a frame's motion the networks are told. The posed mesh carries all
// of it in every mode (canonical samples, the surface texture); what the
// networks are not told they cannot tie to the training frames' look, so an
// expression they never saw is drawn by the mesh rather than by the nearest
// one they memorised.
enum class MotionConditioning {
  kFull,          // neck, jaw, eyes and the expression coefficients (the thesis's avatar)
  kNoExpression,  // neck, jaw and eyes; the expression coefficients are zero
  kNeck,          // the neck's rotation only; jaw, eyes and expression are zero
};
const char* MotionConditioningName(MotionConditioning mode);
MotionConditioning ParseMotionConditioning(const std::string& name);  // throws std::invalid_argument

// What a subject's avatar gets by default (headcast-train subject, create):
// surface-texture channels, its expression blendshapes' texels along an edge
// (held back by SubjectFitDefaults' decay) and the matte.
inline constexpr int kSubjectSurfaceFeatures = 8;
inline constexpr int kSubjectSurfaceBlend = 64;
// AvatarConfig::surface_displacement in the branch's units per metre: an
// expression moves the skin by up to a few centimetres, so the branch sees
// values of about one, as it sees the texture's.
inline constexpr float kSurfaceDisplacementScale = 100;
inline constexpr MatteMode kSubjectMatte = MatteMode::kBounded;
// AvatarConfig::motion_blur's largest exposure, in frame intervals.
inline constexpr double kMaxMotionBlur = 2;
// AvatarConfig::matte_scale a fine-tune writes (bench/DEFAULTS.md).
inline constexpr double kSubjectMatteScale = 0.5;

// The CNeRF backend's configuration: the shared part (output size,
// conditioning sizes) and its own networks, sampling and speed switches.

struct AvatarConfig : AvatarCommonConfig {
  int feature_channels = 48;  // channels of the CNeRF feature vector / feature map
  // CNeRF.
  int pe_frequencies = 6;  // positional-encoding octaves of xyz
  double pe_scale = 0.25;  // metres mapped to 1 before encoding (the head fits in +-1)
  int mlp_width = 96;      // hidden width
  int mlp_layers = 4;      // layers before the density head
  int skip_layer = -1;     // layer whose input also gets the encoded input again (-1: none)
  // CNeRF samples are moved into the canonical (neutral) head through the
  // local frame of the posed triangle under their ray (mesh-guided sampling
  // only), so geometry the head model explains is not the network's to learn.
  // false: rigidly into the head frame, the thesis's configuration.
  bool canonical_samples = false;
  // With canonical samples: the rays beside the silhouette (hair_margin_px,
  // no triangle under them: the hair beyond the head) stay in the head frame,
  // rigid with the skull, instead of following the local frame of the nearest
  // triangle in front — a forehead or cheek that a raised brow or a moved jaw
  // stretches, which would move the hair with it (false in files from before).
  bool rigid_margin = false;
  // With canonical samples: the parts of the mesh that the neutral head
  // covers from the front (CoveredFaces: the mouth's inside behind the closed
  // lips, the eyeballs under the lids) are carried to a place of their own in
  // the canonical space (kCoveredApart), the CNeRF's samples and the texture's
  // points alike. In the neutral head they lie just behind the lips and lids,
  // so a mouth opened or lids raised further than in any training frame
  // showed the networks' lips and lids where the mesh bares what is behind
  // them. false: every part where the neutral head has it.
  bool covered_apart = false;
  // Sampling.
  SamplingMode sampling = SamplingMode::kMeshGuided;
  int samples_per_ray = 8;
  double shell_front = 0.035;  // metres in front of the mesh (hair, lips, glasses)
  double shell_back = 0.02;    // metres behind the mesh
  int hair_margin_px = 2;      // feature-map pixels around the silhouette that still get rays
  double uniform_near = 0.25;  // uniform mode: metres before the head centre
  double uniform_far = 0.25;   // uniform mode: metres after the head centre
  // Speed switches (results identical up to float rounding when on).
  bool precompute_conditioning = true;  // first-layer conditioning term once per frame
  // 2D neural renderer: channels entering each x2 level and leaving the last.
  // Their count sets the levels, hence the feature map's size: four entries,
  // three levels and a map of output/8; three entries, two levels and a map
  // of output/4 (four times the CNeRF's rays, each feature pixel a quarter of
  // the picture's area: finer hair outlines and lids than the 3x3 layers can
  // draw from output/8).
  std::vector<int> renderer_channels = {48, 24, 12, 8};
  // Surface features (0: off, the thesis's configuration): a learned feature
  // texture on the head model's canonical (neutral) surface, stored as three
  // axis-aligned planes, looked up at full output resolution through the
  // rasterised posed mesh and fed to the 2D renderer's last level. The texture
  // moves with the mesh (expressions, blinks) and holds sharp person-specific
  // detail the low-resolution feature map cannot.
  int surface_features = 0;      // channels of the texture
  int surface_resolution = 256;  // texels along each plane edge
  double surface_extent = 0.2;   // metres from the model origin to a plane's edge
  // Pixels just beyond the mesh (hair, the outline) get the texture too: the
  // posed mesh inflated along its normals by this many metres is rasterised,
  // and where it alone covers a pixel the texture is looked up at the
  // canonical mesh inflated alike. The hair's outline then moves with the
  // head and can be drawn as sharply as the face (0: off, the mesh only).
  double surface_shell = 0;
  // A second texture looked up at the posed surface point in the head frame
  // (the rasterised point before the canonical mapping), summed with the
  // first. What sits off the skin but moves with the head (glasses, hair
  // over the cheeks and brow, earrings) is drawn by the skin under it; in
  // the canonical texture that skin moves with every blink, cheek and jaw,
  // and with it what the texture painted there. false: the canonical texture only.
  bool surface_rigid = false;
  // The surface branch is also told, per pixel, how far the expression (and
  // the joints: jaw, eyes, a neck) moved the skin there: the posed surface
  // point less the canonical one (model frame, kSurfaceDisplacementScale per
  // metre), beside the texture's features. What the frame's coefficients say
  // of the whole face, this says of one place: a wide-open mouth no training
  // frame had still stretches each lip and the chin by amounts some training
  // frames stretched them by, where the coefficients' combination is new to
  // the networks. false: the texture's features only.
  bool surface_displacement = false;
  // The texture looked up on the eyeballs by the angle from their pole alone
  // (FoldEyeballPoints): what the video shows of the sclera beside the iris
  // is drawn all around it, where lids that open wider than in any training
  // frame bare the eyeball. false: the eyeball's own point.
  bool surface_eye_symmetry = false;
  // Expression blendshapes of the canonical texture: one set of planes per
  // expression coefficient, of this many texels along an edge, summed with
  // the frame's (told) coefficients as weights and looked up beside the
  // texture. Detail that comes with an expression (a crease, the mouth's
  // inside darkening as it opens) then lives at its own place on the face and
  // grows with the coefficient, where the conditioned branch's per-frame
  // scale and shift act on every pixel alike. 0: none.
  int surface_blend = 0;
  // With surface_blend: 0, one set of planes per coefficient; K > 0, one per
  // principal direction of the subject's training frames' expressions (the
  // first K), the frame's coefficients projected onto them and each held
  // within the range it took on those frames. The coefficients of a few
  // hundred frames move together, so a set per coefficient is fitted along
  // directions the frames barely vary in and adds up what it learnt there on a
  // combination no frame had; the first directions are where the frames do
  // vary. The directions are the texture's (SurfaceTextureImpl::SetBlendBasis),
  // set from the training frames before the blendshapes learn.
  int surface_blend_components = 0;
  // The surface branch's hidden layer is scaled and shifted per frame by the
  // pose and expression (FiLM), so that the texture can hold detail that comes
  // and goes with the expression (forehead wrinkles, creases, the mouth's
  // inside) instead of its average. false: the same branch for every frame.
  bool surface_conditioned = false;
  int surface_hidden = 0;  // the branch's hidden channels (0: twice surface_features, as in files from before)
  // How many of the renderer's x2 levels, counted from the last, the texture
  // joins (1: the last only, as in files from before). At the last level it
  // meets only 1x1 layers, so each pixel's colour is drawn from its own texel;
  // a level before, averaged to that level's size, it passes the next level's
  // dilated 3x3 too, and a lid or brow the mesh moves can shape its neighbours.
  int surface_levels = 1;

  // The outline (kNone in files from before it). A coverage logit, summed over
  // the renderer's levels like its RGB, can turn from 0 to 1 within a pixel
  // wherever its smooth field crosses zero, which RGB that must also match the
  // colours on both sides cannot; the masked targets' outline is sharp.
  MatteMode matte = MatteMode::kNone;
  MatteRules matte_rules;  // kBounded: the rules the training masks were cut with
  // kBounded: the model's silhouette inside the bound, eroded by this fraction
  // of the image edge, is always covered (0: off). The fitted face and skull
  // are the head whatever the learnt coverage says on an expression it saw
  // rarely (a wide-open jaw); the learnt coverage draws the hair beyond them.
  // Off by default: within the run-to-run spread on talking_d9 and d10.
  double matte_core = 0;
  // The coverage logit is multiplied by this where the picture is drawn
  // (below 1: a softer outline); training always draws at 1, a fine-tune
  // writes its choice into the file after it (SubjectOptions::matte_scale).
  // A fine-tune learns each training frame's outline to the pixel, and its
  // coverage turns from 0 to 1 within a pixel or two there; on a frame it
  // never saw, where the hair's outline falls is uncertain by more than
  // that, and an edge drawn as sharply at the wrong place costs more than a
  // softer one. 1 in files from before it. A run-time switch.
  double matte_scale = 1;
  // The camera's exposure in frame intervals: each real frame (training) and
  // each frame of a call (the receiver, from the frame before it) is drawn
  // smeared along the head's image motion over that much of it
  // (motion_blur.h); 0: drawn sharp, as before it existed. A run-time switch.
  double motion_blur = 0;
  // How a frame that carries the top of the head's outline
  // (FrameParams::outline, measured by the sender on its frame) moves the
  // avatar's outline there (outline_warp.h): from this far inside the outline
  // outward, as a share of the picture's height; 0: the frames' outlines are
  // ignored. A run-time switch.
  double outline_ramp = 0.078;
  // The head point the outline's rays start from, (0, y, 0) in the head
  // frame, metres: where the sender measures it from (OutlineOptions).
  double outline_centre_y = OutlineOptions{}.centre_y_m;
  // The coverage logit's scale on a frame whose outline is moved there,
  // instead of matte_scale: matte_scale softens the edge because where the
  // hair's outline falls on an unseen frame is uncertain, and the frame's own
  // outline removes most of that uncertainty. A run-time switch.
  double outline_matte_scale = 1;

  // A run-time switch: the networks' sizes are the same in every mode.
  MotionConditioning motion_conditioning = MotionConditioning::kFull;
  // What the CNeRF samples of the hair are told of the motion, less than the
  // rest (kFull: as every sample). The hair's samples are those of rays over
  // skin that no expression coefficient moves (HairFaces: the scalp, the
  // back of the head, the ears) and of the rays beside the silhouette next to
  // it. Told the expression, the networks can tie the hair's outline of each
  // training frame to that frame's coefficients, and on a held-out frame its
  // coefficients then move the hair where the person's did not; told less,
  // the hair is a function of the skull's pose. Mesh-guided sampling only;
  // a run-time switch.
  MotionConditioning hair_conditioning = MotionConditioning::kFull;
  // The networks are also told the head's rotation as the camera sees it
  // (ViewRotation: a frontal view is zero), composed with the neck's in the
  // neck's place of the conditioning. Tracks that put the head's rotation in
  // the camera transform leave the neck zero, so the networks knew nothing of
  // how the head is turned to the camera and the light: hair that hangs as the
  // head tilts, the shading a fixed light casts on a turned face and the
  // glasses' highlights could only be drawn from codes that happened to go
  // with them. false: the neck alone (the thesis's avatar). A run-time switch.
  bool view_rotation = false;
  // The hair's faces move less than this per unit of any expression
  // coefficient (metres; HairFaces). A run-time switch.
  double hair_reach = 0.003;
  // The expression coefficients the networks are told, each held between the
  // smallest and largest value it took on the subject's training frames; the
  // posed mesh (canonical samples, the surface texture, the matte's bound)
  // still takes the frame's own. Beyond that span the networks would answer
  // inputs they were never trained on (a jaw opened wider than in any
  // training frame drew colour blotches on a cheek); within it the mesh
  // moves what they learnt. Empty: none (general models, files from before
  // it); otherwise num_expression values each, low <= high. A run-time switch.
  std::vector<float> expression_low, expression_high;
  // Added to every frame's conditioning after the span and the motion
  // conditioning have made it (MakeConditioning): the mean of the per-frame
  // offsets a fine-tune learnt on its training frames (METHOD eq. 8). The
  // networks were trained on the tracker's codes plus those offsets, so a
  // frame they never saw, told its codes alone, is told less than the codes
  // they learnt to answer by that mean. Empty: none (general models, files
  // from before it); otherwise conditioning_dim() and appearance_dim()
  // values. A run-time switch.
  std::vector<float> bias_geometry, bias_appearance;

  bool has_surface() const { return surface_features > 0; }
  // The surface lookup needs each mesh pixel's posed point (SurfaceBatch::posed).
  bool needs_posed_points() const { return surface_rigid || surface_displacement; }
  // The surface branch's inputs: the texture's channels [, the displacement's 3].
  int surface_branch_inputs() const { return surface_features + (surface_displacement ? 3 : 0); }
  int surface_hidden_channels() const { return surface_hidden > 0 ? surface_hidden : 2 * surface_features; }
  bool has_matte() const { return matte != MatteMode::kNone; }
  bool has_expression_span() const { return !expression_low.empty(); }
  void ClearExpressionSpan() {
    expression_low.clear();
    expression_high.clear();
  }
  bool has_conditioning_bias() const { return !bias_geometry.empty(); }
  void ClearConditioningBias() {
    bias_geometry.clear();
    bias_appearance.clear();
  }
  // Coefficient i as the networks are told it (within the span, if any).
  float ToldExpression(int i, float value) const;

  int renderer_levels() const { return static_cast<int>(renderer_channels.size()) - 1; }
  int feature_stride() const { return 1 << renderer_levels(); }  // output pixels per feature-map pixel
  int feature_size() const { return output_size / feature_stride(); }
  // The conditioning vector: beta, the neck, jaw and eye rotations (3 each), psi.
  int pose_offset() const { return num_shape; }
  int expression_offset() const { return num_shape + 12; }
  int conditioning_dim() const { return expression_offset() + num_expression; }
  // Whether the motion conditioning tells the networks the conditioning's
  // element i (beta always; the joints and psi as the mode keeps them).
  bool Conditions(int i) const { return Tells(motion_conditioning, i); }
  // Whether `mode` tells the networks the conditioning's element i.
  bool Tells(MotionConditioning mode, int i) const;
  bool has_hair_conditioning() const { return hair_conditioning != MotionConditioning::kFull; }
  int motion_dim() const { return 12 + num_expression; }   // the conditioning without beta: what changes per frame
  int appearance_dim() const { return 27 + num_texture; }  // lambda, tau
  int encoding_dim() const { return 3 + 6 * pe_frequencies; }

  // Throws std::invalid_argument naming each bad field.
  void Check() const;
  nlohmann::json ToJson() const;
  static AvatarConfig FromJson(const nlohmann::json& j);  // checks

  // The shipped default at a resolution, sized for the built-in head model.
  static AvatarConfig Default(int output_size = 256);
  // A configuration the size of HeadNeRF, built from our modules, for side-by-side
  // figures: 32x32x256 feature map, 64 uniform samples, MLP 8 x 384 with a skip at 4.
  static AvatarConfig HeadNeRFSized();
};

// A subject's avatar by default (headcast-train subject and create, the render
// benchmark's subject row): the surface texture with its branch conditioned
// per frame and its expression blendshapes, CNeRF samples in the canonical
// head with the covered parts apart, and the bounded matte. The thesis's
// avatar has none of them.
void ApplySubjectDefaults(AvatarConfig* config);

// The renderer with two x2 levels (a feature map of output/4, four times the
// rays), 4 samples per ray instead of 8 (the CNeRF's cost about twice, not
// four times) and a hair margin of 4 feature-map pixels (the default's reach
// in the picture).
void ApplyTwoLevelRenderer(AvatarConfig* config);

}  // namespace headcast
