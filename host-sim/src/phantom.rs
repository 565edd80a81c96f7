//! Parametric, seeded thorax-cartilage phantom with known ground truth.
//!
//! The phantom stands in for the two point clouds of the registration (a CT template and a
//! patient's US sweep) when no real data are at hand, and — unlike real data — it knows where
//! every template point truly lies on the patient. It is built for testing and evaluating
//! the skeleton-graph registration (SPEC.md, paper section III).
//!
//! # Frame and units
//! Patient frame, millimetres, right-handed: **x** lateral (0 at the midline, +x = the
//! patient's left), **y** cranial, **z** anterior (toward the probe). Angles in degrees in
//! [`SubjectParams`], radians in material coordinates.
//!
//! # Anatomy model
//! Everything hangs on a convex *chest reference surface*
//! `z_chest(x, y) = −x²/(2·R_x) − y²/(2·R_y)` (radii `chest_radius_mm`, 110–170 mm).
//!
//! * **Sternum**: a vertical bar at x = 0 whose horizontal (constant-y) cross-section is a
//!   rounded rectangle `sternum_width_mm` wide (x) and `sternum_thickness_mm` thick (z),
//!   corner radius [`STERNUM_CORNER_FRACTION`] of the half-thickness. Its anterior face lies
//!   `sternum_depth_mm` below the chest surface and follows it along y:
//!   centre `z_st(y) = −y²/(2·R_y) − depth − thickness/2`. It spans from `sternum_margin_mm[0]`
//!   above the rib-2 attachment to `sternum_margin_mm[1]` below the rib-5 attachment; both
//!   ends are rounded over [`STERNUM_CAP_MM`] (the cross-section shrinks like an ellipsoid).
//! * **Costal cartilages** of ribs 2..=5 on each side: tubes with an elliptic cross-section
//!   (`cartilage_width_mm` across, roughly cranio-caudal; `cartilage_thickness_mm` through,
//!   roughly antero-posterior — flatter in that direction) around a centreline parametrised
//!   by the lateral distance `u` from the sternum edge:
//!   - `x = ±(sternum_width/2 + u)`,
//!   - `y = h_k − tan(slope)·u − (drop/100²)·u²` (`slope` from `cartilage_slope_deg`,
//!     `drop` = extra fall at u = [`DROP_REFERENCE_MM`] from `cartilage_drop_mm`; lower
//!     ribs fall laterally),
//!   - `z = −y²/(2·R_y) − (x² − (sternum_width/2)²)/(2·R_x) − depth − thickness/2`: the
//!     centreline follows the convex chest and enters the sternum's lateral face at the
//!     sternum's mid-thickness.
//!
//!   `u` runs from `−`[`CARTILAGE_INSET_MM`] (the medial end, buried inside the sternum so
//!   that the tube joins it) to `cartilage_length_mm` (the lateral tip). The attachment
//!   heights `h_k` are solved so that neighbouring centrelines at the sternum edge (u = 0)
//!   are exactly `rib_spacing_mm` apart (3-D distance; template 31.6 / 26.1 / 24.2 mm, the
//!   paper's L23 / L34 / L45). The tube's flat side faces the chest: its cross-section axes
//!   are the chest normal projected perpendicular to the centreline (`N2`, "anterior") and
//!   `N1 = ±N2 × T` (roughly cranial). The lateral end is closed by an ellipsoidal cap of
//!   length equal to the half-thickness, so every tube is a closed surface except at its
//!   buried medial end.
//! * Finally the whole subject is scaled anisotropically about the origin by `scale`.
//!
//! # Material coordinates
//! A surface point is named by [`Material`] `{ part, s, phi }`, valid on every subject:
//! * cartilage: `s ∈ [0, 1]` linear in `u` from the buried medial end (s = 0) to the lateral
//!   tip (s = 1); `phi` the angle around the tube: 0 = `N1` (cranial side), π/2 = `N2`
//!   (anterior, the side the probe sees), π = caudal, 3π/2 = posterior;
//! * sternum: `s ∈ [0, 1]` from top to bottom (linear in y); `phi/(2π)` the fraction of the
//!   cross-section perimeter, starting at the middle of the patient-left lateral face and
//!   running over the anterior face: 0 = left face, π/2 = anterior face middle, π = right
//!   face, 3π/2 = posterior face.
//!
//! [`SubjectGeometry::surface_point`] (or [`surface_point`]) maps a material coordinate to a
//! position and an outward unit normal on any subject, which is what makes the ground truth
//! of [`PhantomPair::true_position`] exact.
//!
//! # Clouds
//! * CT template: the whole surface of the template subject, Poisson-disc sampled (dart
//!   throwing over an area-weighted, jittered candidate set in material space, accelerated by
//!   a hash grid), spacing `spacing_mm`. Cartilage points strictly inside the sternum and
//!   sternum points strictly inside a cartilage are dropped (the joints are the surface of the
//!   union), the mesh keeps the overlapping surfaces.
//! * US target: the patient's surface sampled the same way at `us_spacing_mm`, keeping
//!   probe-facing points (outward normal z > [`ANTERIOR_MIN_NORMAL_Z`]), then `missing_patches`
//!   spherical holes, Gaussian noise, uniform outliers, a shuffle and a rigid pose.
//!
//! Waypoints ([`WAYPOINT_PLAN`]): five per side in the intercostal gaps (2–3 at s = 0.35
//! and 0.7, 3–4 at 0.35 and 0.7, 4–5 at 0.5): the midpoint of the two neighbouring
//! centreline points at that s, lifted to the mean z of the two anterior surface points
//! (phi = π/2). The same construction on the patient, posed, is the ground truth.
//!
//! As on real data, the US cloud only covers the probe-facing half of each cartilage while
//! the CT cloud covers the whole surface, so skeletons and closest-point distances of a
//! perfect registration differ by about half a cartilage thickness: judge accuracy with
//! [`PhantomPair::true_position`] and the waypoints.
//!
//! # Random subjects
//! [`SubjectParams::random`] perturbs the template (see its docs) and rejects draws whose
//! neighbouring cartilages could come closer than [`MIN_CARTILAGE_GAP_MM`].
//!
//! Everything is a deterministic function of the configuration and its seed: the same
//! [`PhantomConfig`] gives a bit-identical [`PhantomPair`].

use std::f64::consts::TAU;

use ribreg_core::math::rng::Rng;
use serde::{Deserialize, Serialize};

pub mod ct;
mod defects;
mod geometry;
mod mesh;
mod params;
mod pose;
pub(crate) mod sampling;

pub use defects::SweepDefects;
pub use geometry::{surface_point, SubjectGeometry};
pub use params::{Material, Part, Side, Spread, SubjectParams};
pub use pose::Pose;

use params::rib_index;
use sampling::poisson_surface;

// ---------------------------------------------------------------------------------------
// Constants
// ---------------------------------------------------------------------------------------

/// Number of cartilages modelled per side (ribs 2, 3, 4 and 5).
pub const RIB_COUNT: usize = 4;
/// The rib numbers modelled, cranial to caudal.
pub const RIBS: [u8; RIB_COUNT] = [2, 3, 4, 5];
/// Point label of the sternum in a [`LabelledCloud`] (cartilage points carry their rib number).
pub const STERNUM_LABEL: i32 = 1;
/// Minimum clear gap between the surfaces of neighbouring cartilages on every subject, mm.
pub const MIN_CARTILAGE_GAP_MM: f64 = 8.0;
/// Extra clearance the conservative gap bound of a random subject must keep above
/// [`MIN_CARTILAGE_GAP_MM`] (absorbs the centreline discretisation of the bound), mm.
const GAP_SAFETY_MARGIN_MM: f64 = 0.5;
/// Centreline samples per cartilage used by the conservative gap bound.
const GAP_CHECK_SAMPLES: usize = 96;
/// Length of each cartilage's medial end that is buried inside the sternum, mm.
pub const CARTILAGE_INSET_MM: f64 = 3.0;
/// Lateral distance from the sternum edge at which `cartilage_drop_mm` is measured, mm.
pub const DROP_REFERENCE_MM: f64 = 100.0;
/// Length of the rounded ends of the sternum along y, mm.
pub const STERNUM_CAP_MM: f64 = 6.0;
/// Corner radius of the sternum's rounded-rectangle cross-section, as a fraction of its
/// half-thickness (dimensionless).
pub const STERNUM_CORNER_FRACTION: f64 = 0.6;
/// Minimum z-component of the outward unit normal of a surface point the probe can see
/// from the front (dimensionless).
pub const ANTERIOR_MIN_NORMAL_Z: f64 = 0.25;
/// Radius range of the spherical holes cut into the US cloud, mm.
pub const HOLE_RADIUS_RANGE_MM: (f64, f64) = (6.0, 12.0);
/// Margin by which the inlier bounding box is expanded before outliers are drawn in it, mm.
pub const OUTLIER_BOX_MARGIN_MM: f64 = 10.0;
/// Largest rotation of the [`Variant::Aligned`] pose, degrees.
pub const ALIGNED_MAX_ROTATION_DEG: f64 = 3.0;
/// Largest translation of the [`Variant::Aligned`] pose, mm.
pub const ALIGNED_MAX_TRANSLATION_MM: f64 = 5.0;
/// Rotation range of the [`Variant::Misaligned`] pose, degrees.
pub const MISALIGNED_ROTATION_DEG: (f64, f64) = (10.0, 20.0);
/// Translation range of the [`Variant::Misaligned`] pose, mm.
pub const MISALIGNED_TRANSLATION_MM: (f64, f64) = (20.0, 40.0);
/// Smallest Poisson-disc spacing accepted; smaller requests are raised to it, mm.
pub const MIN_SPACING_MM: f64 = 0.5;
/// Candidate points drawn per `spacing²` of surface area before dart throwing
/// (dimensionless; 12 leaves the disc set close to maximal).
const CANDIDATES_PER_SPACING_SQ: f64 = 12.0;
/// Candidate cells per Poisson-disc spacing along each material axis (dimensionless).
const CELLS_PER_SPACING: f64 = 2.0;
/// Samples used to estimate the extent of a part in s and in phi.
const EXTENT_SAMPLES: usize = 64;
/// Upper bound on the number of cells of the dart-throwing hash grid.
const MAX_GRID_CELLS: f64 = 4.0e6;
/// Finite-difference step in material coordinates (s, dimensionless; phi, rad) for
/// normals and area elements.
const FD_STEP: f64 = 1e-6;
/// Target edge length of the template mesh along each part, mm.
pub const MESH_EDGE_MM: f64 = 2.0;
/// Vertices around each cartilage ring of the mesh.
const MESH_TUBE_SEGMENTS: usize = 24;
/// Vertices around each sternum ring of the mesh.
const MESH_STERNUM_SEGMENTS: usize = 40;
/// Rings in each rounded end (cartilage tip, sternum top and bottom) of the mesh.
const MESH_CAP_RINGS: usize = 6;
/// Newton iterations projecting a point onto a cartilage centreline.
const PROJECTION_ITERATIONS: usize = 8;
/// Bisection iterations solving the rib attachment heights.
const BISECTION_ITERATIONS: usize = 80;
/// Random draws tried by [`SubjectParams::random`] before it shrinks toward the template.
const MAX_DRAW_ATTEMPTS: usize = 64;
/// The stretch of s, each way from a waypoint's, whose cartilage cross-sections
/// [`Gap`]'s window is measured against (a tenth of a cartilage is 6–12 mm; a section
/// further along does not come nearer the window on these phantoms:
/// `tests::phantom_waypoint_gaps_end_at_the_cartilages_outlines` checks ±0.2).
const GAP_S_REACH: f64 = 0.1;
/// Cross-sections in that stretch, both ways together (one per 0.001 of s: 0.06–0.12 mm
/// apart along the cartilage).
const GAP_SECTIONS: usize = 200;

/// The window between two ribs a planned waypoint lies in ([`SubjectGeometry::waypoint_gaps`],
/// [`PhantomPair::true_gaps`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Gap {
    /// Unit direction in the chest's plane (perpendicular to the patient's anterior axis)
    /// from the upper rib's centreline toward the lower rib's, at the waypoint's s.
    pub across: [f64; 3],
    /// How far the waypoint may move against `across` before its centre is over the upper
    /// cartilage (mm).
    pub to_upper: f64,
    /// How far it may move along `across` before it is over the lower cartilage (mm).
    pub to_lower: f64,
}

impl Gap {
    /// A mapped waypoint's error `e` (mapped − true) split: its component across the gap
    /// (signed, toward the lower rib positive) and the clearance left to the nearer
    /// cartilage's outline that way (negative: the probe's centre is over a cartilage).
    pub fn split(&self, e: [f64; 3]) -> (f64, f64) {
        let across = dot(e, self.across);
        let clearance = if across >= 0.0 {
            self.to_lower - across
        } else {
            self.to_upper + across
        };
        (across, clearance)
    }
}

/// The planned intercostal waypoints per side: (upper rib of the gap, s along both
/// cartilages). Gap 2–3 at s = 0.35 and 0.7, gap 3–4 at 0.35 and 0.7, gap 4–5 at 0.5.
pub const WAYPOINT_PLAN: [(u8, f64); 5] = [(2, 0.35), (2, 0.7), (3, 0.35), (3, 0.7), (4, 0.5)];

/// Random subjects: a deviation is Gaussian with σ = range / `DRAW_CLIP_SIGMAS`, clipped to
/// ±range (dimensionless). The ranges: [`Spread`].
const DRAW_CLIP_SIGMAS: f64 = 2.0;
/// Number of standard-normal draws behind one random subject.
const N_DRAWS: usize = 3 + 2 + 1 + 1 + 3 + RIB_COUNT * 3 + 2 * RIB_COUNT * 2;

/// Seed stream (derived from [`PhantomConfig::seed`]) of the random patient.
const STREAM_PATIENT: u64 = 1;
/// Seed stream of the template (CT) sampling.
const STREAM_TEMPLATE: u64 = 2;
/// Seed stream of the US sampling and corruption.
const STREAM_US: u64 = 3;
/// Seed stream of the pose.
const STREAM_POSE: u64 = 4;
/// Seed stream of the hard preset's sternum ends (drawn from the patient's seed).
const STREAM_STERNUM: u64 = 6;
/// Range of the hard patients' manubrium: the sternum's top above the rib-2 attachment, mm.
pub const HARD_MANUBRIUM_MM: (f64, f64) = (15.0, 35.0);
/// Range of the hard patients' xiphoid: the sternum's bottom below the rib-5 attachment, mm.
pub const HARD_XIPHOID_MM: (f64, f64) = (20.0, 60.0);

// ---------------------------------------------------------------------------------------
// Small vector helpers (plain f64 arrays)
// ---------------------------------------------------------------------------------------

type P3 = [f64; 3];

/// A triangle mesh: vertices (mm) and triangles as vertex-index triples, wound so that
/// the right-hand normal points out of the body.
pub type Mesh = (Vec<[f64; 3]>, Vec<[u32; 3]>);

fn add(a: P3, b: P3) -> P3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
fn sub(a: P3, b: P3) -> P3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn mul(a: P3, k: f64) -> P3 {
    [a[0] * k, a[1] * k, a[2] * k]
}
fn dot(a: P3, b: P3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: P3, b: P3) -> P3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn norm(a: P3) -> f64 {
    dot(a, a).sqrt()
}
fn dist2(a: P3, b: P3) -> f64 {
    let d = sub(a, b);
    dot(d, d)
}
/// `a / |a|`, or `fallback` when `a` is (numerically) zero.
fn normalize_or(a: P3, fallback: P3) -> P3 {
    let n = norm(a);
    if n > 1e-300 && n.is_finite() {
        mul(a, 1.0 / n)
    } else {
        fallback
    }
}
fn midpoint(a: P3, b: P3) -> P3 {
    mul(add(a, b), 0.5)
}

/// One standard-normal draw (Box–Muller on two uniforms; the sine branch is discarded so
/// every draw consumes exactly two `next_f64`).
pub fn gaussian(rng: &mut Rng) -> f64 {
    let u1 = 1.0 - rng.next_f64(); // (0, 1]: ln stays finite
    let u2 = rng.next_f64();
    (-2.0 * u1.ln()).sqrt() * (TAU * u2).cos()
}

/// A uniformly distributed unit vector (normalised Gaussian triple).
fn random_unit(rng: &mut Rng) -> P3 {
    for _ in 0..16 {
        let v = [gaussian(rng), gaussian(rng), gaussian(rng)];
        let n = norm(v);
        if n > 1e-6 {
            return mul(v, 1.0 / n);
        }
    }
    [0.0, 0.0, 1.0]
}

/// Uniform draw in `[lo, hi)`.
fn uniform(rng: &mut Rng, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * rng.next_f64()
}

/// Fisher–Yates shuffle driven by `rng`.
fn shuffle<T>(v: &mut [T], rng: &mut Rng) {
    for i in (1..v.len()).rev() {
        let j = rng.below((i + 1) as u32) as usize;
        v.swap(i, j);
    }
}

/// An independent seed for one stream of a configuration seed.
fn derive_seed(seed: u64, stream: u64) -> u64 {
    Rng::new(seed ^ stream.wrapping_mul(0xA076_1D64_78BD_642F)).next_u64()
}

// ---------------------------------------------------------------------------------------
// Configuration and the phantom pair
// ---------------------------------------------------------------------------------------

/// How far the US target is posed away from the patient frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
pub enum Variant {
    /// Nearly aligned: rotation up to [`ALIGNED_MAX_ROTATION_DEG`] about a random axis,
    /// translation up to [`ALIGNED_MAX_TRANSLATION_MM`].
    Aligned,
    /// Grossly misaligned: rotation in [`MISALIGNED_ROTATION_DEG`] about a random axis,
    /// translation in [`MISALIGNED_TRANSLATION_MM`].
    Misaligned,
}

/// A family of phantoms: how much the patients vary and how imperfect their sweeps are.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Preset {
    /// The phantoms of every figure before issue 12 (kept so that old and new results
    /// compare): [`Spread::STANDARD`] patients, the template's sternum ends, holes
    /// anywhere, every cartilage seen to its tip, no breathing.
    #[default]
    Standard,
    /// Harder: [`Spread::HARD`] patients (lengths ±20 %, asymmetry ±12 %, slopes ±7°),
    /// a manubrium 15–35 mm above rib 2 and a xiphoid 20–60 mm below rib 5, and the
    /// [`SweepDefects`]: two more holes on lateral tips, each costochondral junction seen
    /// only in part (from 80–95 % of a cartilage's length to its tip, 40 % of the points
    /// seen), breathing of 2–6 mm at 0.2–0.3 Hz during a raster sweep.
    Hard,
}

/// One difficulty of the [`Preset::Hard`] phantoms, which
/// [`PhantomConfig::hard_without`] can leave out: an ablation of the phantom, to see what
/// each costs a method.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum HardPart {
    /// The wider patient variation ([`Spread::HARD`]; without: [`Spread::STANDARD`]).
    Spread,
    /// The manubrium and xiphoid (without: the template's sternum ends).
    Sternum,
    /// The holes on lateral tips.
    TipHoles,
    /// The partly seen costochondral junctions.
    Junction,
    /// Breathing during the sweep.
    Breathing,
}

impl HardPart {
    /// The difficulties of the sweep, not of the patient.
    pub const SWEEP: [HardPart; 3] = [HardPart::TipHoles, HardPart::Junction, HardPart::Breathing];

    /// Name in tables and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            HardPart::Spread => "spread",
            HardPart::Sternum => "sternum",
            HardPart::TipHoles => "tip-holes",
            HardPart::Junction => "junction",
            HardPart::Breathing => "breathing",
        }
    }
}

impl Preset {
    /// Both presets, standard first.
    pub const ALL: [Preset; 2] = [Preset::Standard, Preset::Hard];

    /// Name in tables, files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Preset::Standard => "standard",
            Preset::Hard => "hard",
        }
    }
}

/// Phantom generation settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PhantomConfig {
    /// CT template Poisson-disc spacing, mm (default 2.5; at least [`MIN_SPACING_MM`]).
    pub spacing_mm: f64,
    /// US target Poisson-disc spacing, mm (default 2.0; at least [`MIN_SPACING_MM`]).
    pub us_spacing_mm: f64,
    /// Standard deviation of the US noise per coordinate, mm (default 0.7).
    pub us_noise_mm: f64,
    /// Outliers added, as a fraction of the US inlier count (default 0.01; clamped to [0, 1]).
    pub outlier_fraction: f64,
    /// Spherical holes cut into the US cloud (default 3).
    pub missing_patches: usize,
    /// Pose variant of the US target (default aligned).
    pub variant: Variant,
    /// Seed of every random choice (default 0).
    pub seed: u64,
    /// Which family of phantoms (default [`Preset::Standard`]).
    #[serde(default)]
    pub preset: Preset,
    /// [`Preset::Hard`]: difficulties left out (default none; ignored for the standard
    /// preset). With all five left out a hard phantom is the standard one.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub hard_without: Vec<HardPart>,
}

impl Default for PhantomConfig {
    fn default() -> Self {
        Self {
            spacing_mm: 2.5,
            us_spacing_mm: 2.0,
            us_noise_mm: 0.7,
            outlier_fraction: 0.01,
            missing_patches: 3,
            variant: Variant::Aligned,
            seed: 0,
            preset: Preset::Standard,
            hard_without: Vec::new(),
        }
    }
}

impl PhantomConfig {
    /// A copy with out-of-range values replaced: spacings below [`MIN_SPACING_MM`] (or NaN)
    /// raised to it, negative/NaN noise set to 0, the outlier fraction clamped to [0, 1].
    pub fn sanitized(&self) -> Self {
        let spacing = |v: f64| {
            if v.is_finite() {
                v.max(MIN_SPACING_MM)
            } else {
                MIN_SPACING_MM
            }
        };
        Self {
            spacing_mm: spacing(self.spacing_mm),
            us_spacing_mm: spacing(self.us_spacing_mm),
            us_noise_mm: if self.us_noise_mm.is_finite() {
                self.us_noise_mm.max(0.0)
            } else {
                0.0
            },
            outlier_fraction: if self.outlier_fraction.is_finite() {
                self.outlier_fraction.clamp(0.0, 1.0)
            } else {
                0.0
            },
            ..self.clone()
        }
    }
}

/// A point cloud with a label (1 = sternum, 2..=5 = rib) and material coordinates per point.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LabelledCloud {
    /// Points, mm.
    pub points: Vec<[f64; 3]>,
    /// Label per point: [`STERNUM_LABEL`] or the rib number.
    pub labels: Vec<i32>,
    /// Material coordinates per point.
    pub material: Vec<Material>,
}

/// A CT template and a US target of one (random) patient, with the ground truth linking them.
#[derive(Clone, Debug, PartialEq)]
pub struct PhantomPair {
    /// The configuration the pair was generated with (sanitised).
    pub config: PhantomConfig,
    /// Shape of the CT template subject (sanitised).
    pub template_params: SubjectParams,
    /// Shape of the patient (sanitised).
    pub patient_params: SubjectParams,
    /// CT: the template's whole surface, Poisson-disc sampled (template frame = patient
    /// frame of the template subject).
    pub template: LabelledCloud,
    /// CT surface as a triangle mesh (vertices, outward-wound triangles), template frame.
    pub template_mesh: Mesh,
    /// US: the patient's probe-facing surface, noisy, with holes and outliers, posed into
    /// the target frame (shuffled).
    pub target: Vec<[f64; 3]>,
    /// Material coordinates of each target point on the patient (noise-free), `None` for
    /// outliers.
    pub target_material: Vec<Option<Material>>,
    /// Patient frame → US (target) frame.
    pub pose: Pose,
    /// The planned intercostal waypoints on the template, template frame (order: see
    /// [`SubjectGeometry::waypoints`]).
    pub template_waypoints: Vec<[f64; 3]>,
    /// The same waypoints on the patient, target frame: the ground truth of waypoint mapping.
    pub true_waypoints: Vec<[f64; 3]>,
    /// The sweep's defects ([`Preset::Hard`]; `None` for the standard phantoms).
    pub defects: Option<SweepDefects>,
}

/// The mean of `points` (the origin for none).
pub fn centroid(points: &[[f64; 3]]) -> [f64; 3] {
    let n = points.len().max(1) as f64;
    points.iter().fold([0.0; 3], |a, p| {
        [a[0] + p[0] / n, a[1] + p[1] / n, a[2] + p[2] / n]
    })
}

impl PhantomPair {
    /// The pair for `cfg`: template = [`SubjectParams::template`], patient =
    /// [`SubjectParams::random_for`] its preset with a seed derived from `cfg.seed`.
    pub fn generate(cfg: &PhantomConfig) -> PhantomPair {
        let patient = SubjectParams::random_for(
            derive_seed(cfg.seed, STREAM_PATIENT),
            cfg.preset,
            &cfg.hard_without,
        );
        Self::generate_with(&SubjectParams::template(), &patient, cfg)
    }

    /// The pair for explicit template and patient shapes; all sampling, corruption and the
    /// pose are drawn from seeds derived from `cfg.seed`.
    pub fn generate_with(
        template: &SubjectParams,
        patient: &SubjectParams,
        cfg: &PhantomConfig,
    ) -> PhantomPair {
        let cfg = cfg.sanitized();
        let tg = SubjectGeometry::new(template);
        let pg = SubjectGeometry::new(patient);

        // CT template.
        let mut rng = Rng::new(derive_seed(cfg.seed, STREAM_TEMPLATE));
        let (points, material) = poisson_surface(&tg, cfg.spacing_mm, &mut rng);
        let labels = material.iter().map(|m| m.part.label()).collect();
        let template_cloud = LabelledCloud {
            points,
            labels,
            material,
        };
        let template_mesh = tg.mesh(MESH_EDGE_MM);

        // US target on the patient.
        let mut rng = Rng::new(derive_seed(cfg.seed, STREAM_US));
        let (points, materials) = poisson_surface(&pg, cfg.us_spacing_mm, &mut rng);
        let mut seen: Vec<(P3, Material)> = points
            .into_iter()
            .zip(materials)
            .filter(|(_, m)| pg.surface_point(m).1[2] > ANTERIOR_MIN_NORMAL_Z)
            .collect();
        for _ in 0..cfg.missing_patches {
            if seen.is_empty() {
                break;
            }
            let centre = seen[rng.below(seen.len() as u32) as usize].0;
            let radius = uniform(&mut rng, HOLE_RADIUS_RANGE_MM.0, HOLE_RADIUS_RANGE_MM.1);
            seen.retain(|(p, _)| dist2(*p, centre) > radius * radius);
        }
        let defects = (cfg.preset == Preset::Hard).then(|| {
            let (mut d, mut drng) = SweepDefects::draw(cfg.seed, &cfg.hard_without);
            d.apply(&pg, &mut seen, &mut drng);
            d
        });
        let mut target: Vec<(P3, Option<Material>)> = seen
            .into_iter()
            .map(|(p, m)| {
                let noise = [gaussian(&mut rng), gaussian(&mut rng), gaussian(&mut rng)];
                (add(p, mul(noise, cfg.us_noise_mm)), Some(m))
            })
            .collect();
        let n_outliers = (cfg.outlier_fraction * target.len() as f64).round() as usize;
        if n_outliers > 0 {
            let mut lo = [f64::INFINITY; 3];
            let mut hi = [f64::NEG_INFINITY; 3];
            for (p, _) in &target {
                for a in 0..3 {
                    lo[a] = lo[a].min(p[a] - OUTLIER_BOX_MARGIN_MM);
                    hi[a] = hi[a].max(p[a] + OUTLIER_BOX_MARGIN_MM);
                }
            }
            for _ in 0..n_outliers {
                let p = [
                    uniform(&mut rng, lo[0], hi[0]),
                    uniform(&mut rng, lo[1], hi[1]),
                    uniform(&mut rng, lo[2], hi[2]),
                ];
                target.push((p, None));
            }
        }
        shuffle(&mut target, &mut rng);

        let pose = Pose::random(
            cfg.variant,
            &mut Rng::new(derive_seed(cfg.seed, STREAM_POSE)),
        );
        let (target, target_material) = target.into_iter().map(|(p, m)| (pose.apply(p), m)).unzip();
        let template_waypoints = tg.waypoints();
        let true_waypoints = pg.waypoints().into_iter().map(|p| pose.apply(p)).collect();

        PhantomPair {
            config: cfg,
            template_params: tg.params().clone(),
            patient_params: pg.params().clone(),
            template: template_cloud,
            template_mesh,
            target,
            target_material,
            pose,
            template_waypoints,
            true_waypoints,
            defects,
        }
    }

    /// Where template point `template_index` truly lies on the patient, in the target frame.
    /// An index past the end yields the patient's centre of the sternum top (never panics;
    /// check the index against `template.points.len()`).
    pub fn true_position(&self, template_index: usize) -> [f64; 3] {
        let m = self
            .template
            .material
            .get(template_index)
            .copied()
            .unwrap_or(Material {
                part: Part::Sternum,
                s: 0.0,
                phi: 0.0,
            });
        self.pose
            .apply(SubjectGeometry::new(&self.patient_params).position(&m))
    }

    /// The windows of the true waypoints ([`SubjectGeometry::waypoint_gaps`] of the
    /// patient, turned into the target frame; same order as `true_waypoints`).
    pub fn true_gaps(&self) -> Vec<Gap> {
        SubjectGeometry::new(&self.patient_params)
            .waypoint_gaps()
            .into_iter()
            .map(|g| Gap {
                across: self.pose.apply_vector(g.across),
                ..g
            })
            .collect()
    }

    /// Each mapped waypoint's error against the true one split by its window
    /// ([`Gap::split`]: the signed component across the gap and the clearance left), in
    /// the order of `true_waypoints`; `mapped` in the target frame.
    pub fn across_the_gaps(&self, mapped: &[[f64; 3]]) -> Vec<(f64, f64)> {
        mapped
            .iter()
            .zip(&self.true_waypoints)
            .zip(self.true_gaps())
            .map(|((m, t), g)| g.split(sub(*m, *t)))
            .collect()
    }

    /// [`PhantomPair::true_position`] of every template point (solves the patient's
    /// geometry once).
    pub fn true_positions(&self) -> Vec<[f64; 3]> {
        let pg = SubjectGeometry::new(&self.patient_params);
        self.template
            .material
            .iter()
            .map(|m| self.pose.apply(pg.position(m)))
            .collect()
    }

    /// [`PhantomPair::true_positions`], but with each sternum point's truth at the same
    /// share of the way between the same two of the sternum's landmarks (its ends and the
    /// rib attachments, [`SubjectGeometry::sternum_s_by_landmarks`]) rather than at the
    /// same share of its whole length: the correspondence of anatomy, where the hard
    /// preset's manubrium and xiphoid vary apart from the ribs'. The cartilages' truth
    /// is unchanged.
    pub fn true_positions_by_landmarks(&self) -> Vec<[f64; 3]> {
        let pg = SubjectGeometry::new(&self.patient_params);
        let tg = SubjectGeometry::new(&self.template_params);
        self.template
            .material
            .iter()
            .map(|m| {
                let m = match m.part {
                    Part::Sternum => Material {
                        s: pg.sternum_s_by_landmarks(&tg, m.s),
                        ..*m
                    },
                    Part::Cartilage { .. } => *m,
                };
                self.pose.apply(pg.position(&m))
            })
            .collect()
    }

    /// The template's labels as the core takes them (rib 2..=5, 1 sternum; any other
    /// value 0, none).
    pub fn core_labels(&self) -> Vec<u8> {
        self.template
            .labels
            .iter()
            .map(|&l| u8::try_from(l).unwrap_or(0))
            .collect()
    }

    /// How far along each cartilage the sweep reaches: per side ([`Side::index`]) and rib
    /// (2..=5), the largest material `s` among the target's points on it (0 where it has
    /// none).
    pub fn sweep_reach(&self) -> [[f64; RIB_COUNT]; 2] {
        let mut reach = [[0.0f64; RIB_COUNT]; 2];
        for m in self.target_material.iter().flatten() {
            if let Part::Cartilage { rib, side } = m.part {
                let r = &mut reach[side.index()][rib_index(rib)];
                *r = r.max(m.s);
            }
        }
        reach
    }

    /// The true waypoints (indices into `true_waypoints`) that the sweep does not reach:
    /// a cartilage bounding the waypoint's gap shows no point as far out as the waypoint
    /// (a sweep hole or a lost lateral tip took it). No registration can support such a
    /// waypoint, so a sweep with one is not complete coverage.
    pub fn unreached_waypoints(&self) -> Vec<usize> {
        let reach = self.sweep_reach();
        Side::BOTH
            .iter()
            .flat_map(|&side| WAYPOINT_PLAN.iter().map(move |&p| (side, p)))
            .enumerate()
            .filter(|(_, (side, (upper, s)))| {
                [*upper, upper + 1]
                    .iter()
                    .any(|&rib| reach[side.index()][rib_index(rib)] < *s)
            })
            .map(|(i, _)| i)
            .collect()
    }

    /// The same pair with its target frame moved by `by` (the old target frame into the
    /// new): the target's points, the pose and the true waypoints move together; the
    /// template and its plan stay.
    pub fn moved(mut self, by: &Pose) -> PhantomPair {
        for p in self.target.iter_mut().chain(&mut self.true_waypoints) {
            *p = by.apply(*p);
        }
        self.pose = by.compose(&self.pose);
        self
    }

    /// The same pair with the robot base turned by `deg` degrees about the patient's
    /// anterior axis through the target's centroid ([`PhantomPair::moved`]): where the
    /// robot stands against the bed (at 180° it stands at the other end).
    pub fn turned(self, deg: f64) -> PhantomPair {
        if deg == 0.0 {
            return self;
        }
        let anterior = self.pose.apply_vector([0.0, 0.0, 1.0]);
        let turn = Pose::about(anterior, deg.to_radians(), centroid(&self.target));
        self.moved(&turn)
    }

    /// Number of outliers in the target.
    pub fn outlier_count(&self) -> usize {
        self.target_material.iter().filter(|m| m.is_none()).count()
    }

    /// Parameters to save beside the generated files: configuration, both subjects, pose,
    /// point counts and waypoints.
    pub fn write_params_json(&self) -> serde_json::Value {
        serde_json::json!({
            "config": self.config,
            "template_params": self.template_params,
            "patient_params": self.patient_params,
            "pose": self.pose,
            "pose_rotation_deg": self.pose.rotation_angle_deg(),
            "pose_translation_mm": self.pose.translation_norm(),
            "counts": {
                "template": self.template.points.len(),
                "target": self.target.len(),
                "target_outliers": self.outlier_count(),
                "mesh_vertices": self.template_mesh.0.len(),
                "mesh_triangles": self.template_mesh.1.len(),
            },
            "template_waypoints": self.template_waypoints,
            "true_waypoints": self.true_waypoints,
            "sweep_defects": self.defects,
        })
    }
}

#[cfg(test)]
mod tests;
