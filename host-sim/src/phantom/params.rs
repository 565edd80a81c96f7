//! Material coordinates and subject shape parameters (see the parent module docs).

use serde::{Deserialize, Serialize};

use super::*;

// ---------------------------------------------------------------------------------------
// Material coordinates
// ---------------------------------------------------------------------------------------

/// Body side of a cartilage. Left is the patient's left, +x.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Side {
    /// The patient's left (+x).
    Left,
    /// The patient's right (−x).
    Right,
}

impl Side {
    /// Both sides, left first (the order of waypoints and parameter arrays).
    pub const BOTH: [Side; 2] = [Side::Left, Side::Right];

    /// +1 for the left (+x) side, −1 for the right.
    pub fn sign(self) -> f64 {
        match self {
            Side::Left => 1.0,
            Side::Right => -1.0,
        }
    }

    /// Index into the `[side][rib]` arrays of [`SubjectParams`]: 0 = left, 1 = right.
    pub fn index(self) -> usize {
        match self {
            Side::Left => 0,
            Side::Right => 1,
        }
    }
}

/// One anatomical part of the phantom.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Part {
    /// The sternum (label 1).
    Sternum,
    /// The costal cartilage of rib `rib` (2..=5; other values are clamped) on `side`.
    Cartilage {
        /// Rib number, 2..=5.
        rib: u8,
        /// Body side.
        side: Side,
    },
}

impl Part {
    /// All nine parts: the sternum, then the left cartilages 2..5, then the right ones.
    pub const ALL: [Part; 1 + 2 * RIB_COUNT] = [
        Part::Sternum,
        Part::Cartilage {
            rib: 2,
            side: Side::Left,
        },
        Part::Cartilage {
            rib: 3,
            side: Side::Left,
        },
        Part::Cartilage {
            rib: 4,
            side: Side::Left,
        },
        Part::Cartilage {
            rib: 5,
            side: Side::Left,
        },
        Part::Cartilage {
            rib: 2,
            side: Side::Right,
        },
        Part::Cartilage {
            rib: 3,
            side: Side::Right,
        },
        Part::Cartilage {
            rib: 4,
            side: Side::Right,
        },
        Part::Cartilage {
            rib: 5,
            side: Side::Right,
        },
    ];

    /// Cloud label: [`STERNUM_LABEL`] (1) for the sternum, the rib number for a cartilage.
    pub fn label(self) -> i32 {
        match self {
            Part::Sternum => STERNUM_LABEL,
            Part::Cartilage { rib, .. } => i32::from(rib_index(rib) as u8 + 2),
        }
    }
}

/// Index 0..4 of a rib number 2..=5 (out-of-range numbers are clamped).
pub(super) fn rib_index(rib: u8) -> usize {
    usize::from(rib.clamp(2, 5) - 2)
}

/// Material coordinates of a surface point, valid on every subject (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Material {
    /// The part the point lies on.
    pub part: Part,
    /// Position along the part in [0, 1]: cartilage from the medial (sternum) end to the
    /// lateral tip, sternum from top to bottom. Values outside are clamped.
    pub s: f64,
    /// Angle around the part, radians (any value; taken modulo 2π).
    pub phi: f64,
}

// ---------------------------------------------------------------------------------------
// Subject parameters
// ---------------------------------------------------------------------------------------

/// Shape parameters of one subject (template or patient). Lengths in mm, angles in degrees.
/// `[side][rib]` arrays are indexed by [`Side::index`] (0 = left) and rib − 2.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SubjectParams {
    /// Anisotropic scale [x, y, z] applied last, about the origin (dimensionless; 1 = none).
    pub scale: [f64; 3],
    /// Radii of curvature of the chest reference surface [R_x lateral, R_y cranio-caudal], mm.
    pub chest_radius_mm: [f64; 2],
    /// Sternum width (x), mm.
    pub sternum_width_mm: f64,
    /// Sternum thickness (z), mm.
    pub sternum_thickness_mm: f64,
    /// Depth of the sternum's anterior face below the chest reference surface, mm.
    pub sternum_depth_mm: f64,
    /// Extension of the sternum [above the rib-2, below the rib-5] attachment, mm.
    pub sternum_margin_mm: [f64; 2],
    /// Height y of the rib-2 centreline at the sternum edge, mm.
    pub rib2_height_mm: f64,
    /// 3-D distance between neighbouring centrelines at the sternum edge [2–3, 3–4, 4–5], mm.
    pub rib_spacing_mm: [f64; 3],
    /// Cartilage cross-section diameter across the tube (along `N1`, ≈ y) per rib, mm.
    pub cartilage_width_mm: [f64; RIB_COUNT],
    /// Cartilage cross-section diameter through the tube (along `N2`, ≈ z) per rib, mm.
    pub cartilage_thickness_mm: [f64; RIB_COUNT],
    /// Lateral length from the sternum edge to the tip, `[side][rib − 2]`, mm.
    pub cartilage_length_mm: [[f64; RIB_COUNT]; 2],
    /// Slope of the centreline at the sternum, downward going laterally, `[side][rib − 2]`, deg.
    pub cartilage_slope_deg: [[f64; RIB_COUNT]; 2],
    /// Extra (quadratic) fall of the centreline at u = [`DROP_REFERENCE_MM`],
    /// `[side][rib − 2]`, mm.
    pub cartilage_drop_mm: [[f64; RIB_COUNT]; 2],
}

impl SubjectParams {
    /// The fixed mean subject used as the CT template. Its rib spacings at the sternum are
    /// the paper's L23 = 31.6, L34 = 26.1, L45 = 24.2 mm.
    pub fn template() -> Self {
        Self {
            scale: [1.0, 1.0, 1.0],
            chest_radius_mm: [135.0, 160.0],
            sternum_width_mm: 28.0,
            sternum_thickness_mm: 10.0,
            sternum_depth_mm: 8.0,
            sternum_margin_mm: [20.0, 25.0],
            rib2_height_mm: 40.0,
            rib_spacing_mm: [31.6, 26.1, 24.2],
            cartilage_width_mm: [10.0, 11.0, 11.0, 12.0],
            cartilage_thickness_mm: [8.0, 8.0, 8.5, 8.5],
            cartilage_length_mm: [[62.0, 75.0, 88.0, 100.0]; 2],
            cartilage_slope_deg: [[-5.0, 0.0, 8.0, 15.0]; 2],
            cartilage_drop_mm: [[0.0, 5.0, 10.0, 15.0]; 2],
        }
    }

    /// A plausible random patient of the [`Preset::Standard`] phantoms, deterministic in
    /// `seed`: anisotropic scale ±10 %, chest radii ±15 %, sternum width ±10 %, one
    /// thickness factor ±20 % (cartilages and sternum), rib spacings ±15 %, lengths ±15 %,
    /// slopes ±4°, drops ±15 %, and a left/right asymmetry of ±5 % per side and rib on
    /// lengths and on slopes/drops. Each deviation is a Gaussian with σ = half its range,
    /// clipped to the range.
    ///
    /// Draws whose neighbouring cartilages could come closer than [`MIN_CARTILAGE_GAP_MM`]
    /// are rejected; after 64 rejections the last draw is shrunk toward
    /// the template (which satisfies the gap) until it passes.
    pub fn random(seed: u64) -> Self {
        Self::random_with(seed, &Spread::STANDARD)
    }

    /// A random patient of `preset` (see [`Preset`]): [`SubjectParams::random`] for the
    /// standard phantoms; for the hard ones the wider [`Spread::HARD`] and a manubrium
    /// [`HARD_MANUBRIUM_MM`] above rib 2 and a xiphoid [`HARD_XIPHOID_MM`] below rib 5
    /// (uniform, from a stream of their own, so the rest of the draw is the standard
    /// one's shape); `without` leaves out [`HardPart::Spread`] (the standard spread)
    /// or [`HardPart::Sternum`] (the template's sternum ends).
    pub fn random_for(seed: u64, preset: Preset, without: &[HardPart]) -> Self {
        match preset {
            Preset::Standard => Self::random(seed),
            Preset::Hard => {
                let spread = if without.contains(&HardPart::Spread) {
                    &Spread::STANDARD
                } else {
                    &Spread::HARD
                };
                let mut p = Self::random_with(seed, spread);
                if without.contains(&HardPart::Sternum) {
                    return p;
                }
                let mut rng = Rng::new(derive_seed(seed, STREAM_STERNUM));
                p.sternum_margin_mm = [
                    uniform(&mut rng, HARD_MANUBRIUM_MM.0, HARD_MANUBRIUM_MM.1),
                    uniform(&mut rng, HARD_XIPHOID_MM.0, HARD_XIPHOID_MM.1),
                ];
                p
            }
        }
    }

    /// [`SubjectParams::random`] with the deviations of `spread`.
    fn random_with(seed: u64, spread: &Spread) -> Self {
        let mut rng = Rng::new(seed);
        let mut z = [0.0; N_DRAWS];
        for _ in 0..MAX_DRAW_ATTEMPTS {
            z.iter_mut().for_each(|v| *v = gaussian(&mut rng));
            let p = Self::from_draws(&z, 1.0, spread);
            if p.gap_is_safe() {
                return p;
            }
        }
        let mut t = 0.5;
        while t > 1e-3 {
            let p = Self::from_draws(&z, t, spread);
            if p.gap_is_safe() {
                return p;
            }
            t *= 0.5;
        }
        Self::template()
    }

    /// The subject for standard-normal draws `z`, each deviation (ranges of `spread`)
    /// multiplied by `t` (t = 0 gives the template exactly).
    pub(super) fn from_draws(z: &[f64; N_DRAWS], t: f64, spread: &Spread) -> Self {
        let mut k = 0usize;
        let mut next = || {
            let v = z.get(k).copied().unwrap_or(0.0);
            k += 1;
            t * v.clamp(-DRAW_CLIP_SIGMAS, DRAW_CLIP_SIGMAS) / DRAW_CLIP_SIGMAS
        };
        let mut p = Self::template();
        p.scale
            .iter_mut()
            .for_each(|v| *v *= 1.0 + spread.scale * next());
        p.chest_radius_mm
            .iter_mut()
            .for_each(|v| *v *= 1.0 + spread.chest_radius * next());
        p.sternum_width_mm *= 1.0 + spread.sternum_width * next();
        let thickness = 1.0 + spread.thickness * next();
        p.sternum_thickness_mm *= thickness;
        p.cartilage_width_mm
            .iter_mut()
            .for_each(|v| *v *= thickness);
        p.cartilage_thickness_mm
            .iter_mut()
            .for_each(|v| *v *= thickness);
        p.rib_spacing_mm
            .iter_mut()
            .for_each(|v| *v *= 1.0 + spread.spacing * next());
        for r in 0..RIB_COUNT {
            let length = 1.0 + spread.length * next();
            let slope = spread.slope_deg * next();
            let drop = 1.0 + spread.drop * next();
            for side in 0..2 {
                p.cartilage_length_mm[side][r] *= length;
                p.cartilage_slope_deg[side][r] += slope;
                p.cartilage_drop_mm[side][r] *= drop;
            }
        }
        for side in 0..2 {
            for r in 0..RIB_COUNT {
                p.cartilage_length_mm[side][r] *= 1.0 + spread.asymmetry * next();
                let a = 1.0 + spread.asymmetry * next();
                p.cartilage_slope_deg[side][r] *= a;
                p.cartilage_drop_mm[side][r] *= a;
            }
        }
        p
    }

    /// A copy with every value forced into a physically meaningful range (NaN and
    /// non-positive sizes are raised to small positive minima). Idempotent.
    pub fn sanitized(&self) -> Self {
        fn at_least(v: f64, min: f64) -> f64 {
            v.max(min) // f64::max ignores NaN
        }
        fn finite(v: f64) -> f64 {
            if v.is_finite() {
                v
            } else {
                0.0
            }
        }
        let mut p = self.clone();
        p.scale
            .iter_mut()
            .for_each(|v| *v = at_least(finite(*v), 0.1));
        p.chest_radius_mm
            .iter_mut()
            .for_each(|v| *v = at_least(finite(*v), 20.0));
        p.sternum_width_mm = at_least(finite(p.sternum_width_mm), 2.0 * CARTILAGE_INSET_MM);
        p.sternum_thickness_mm = at_least(finite(p.sternum_thickness_mm), 1.0);
        p.sternum_depth_mm = finite(p.sternum_depth_mm);
        p.sternum_margin_mm
            .iter_mut()
            .for_each(|v| *v = at_least(finite(*v), STERNUM_CAP_MM));
        p.rib2_height_mm = finite(p.rib2_height_mm);
        p.rib_spacing_mm
            .iter_mut()
            .for_each(|v| *v = at_least(finite(*v), 1.0));
        p.cartilage_width_mm
            .iter_mut()
            .for_each(|v| *v = at_least(finite(*v), 0.5));
        p.cartilage_thickness_mm
            .iter_mut()
            .for_each(|v| *v = at_least(finite(*v), 0.5));
        for side in 0..2 {
            p.cartilage_length_mm[side]
                .iter_mut()
                .for_each(|v| *v = at_least(finite(*v), 10.0));
            p.cartilage_slope_deg[side]
                .iter_mut()
                .for_each(|v| *v = finite(*v).clamp(-60.0, 60.0));
            p.cartilage_drop_mm[side]
                .iter_mut()
                .for_each(|v| *v = finite(*v));
        }
        p
    }

    /// Whether the conservative gap bound clears [`MIN_CARTILAGE_GAP_MM`] plus the safety margin.
    pub(super) fn gap_is_safe(&self) -> bool {
        SubjectGeometry::new(self).min_gap_lower_bound()
            >= MIN_CARTILAGE_GAP_MM + GAP_SAFETY_MARGIN_MM
    }
}

/// How far a random patient may deviate from the template: each is the range (±) of one
/// Gaussian deviation (σ = half the range, clipped to it); relative unless named `_deg`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spread {
    /// Anisotropic scale, per axis.
    pub scale: f64,
    /// Chest radii.
    pub chest_radius: f64,
    /// Sternum width.
    pub sternum_width: f64,
    /// The thickness factor shared by all cartilages and the sternum.
    pub thickness: f64,
    /// Each rib spacing at the sternum.
    pub spacing: f64,
    /// Each cartilage length (both sides).
    pub length: f64,
    /// Each cartilage slope (both sides), degrees.
    pub slope_deg: f64,
    /// Each cartilage drop (both sides).
    pub drop: f64,
    /// Left/right asymmetry of lengths and of slopes/drops, per side and rib.
    pub asymmetry: f64,
}

impl Spread {
    /// The standard phantoms' patients (every figure before issue 12's harder phantoms).
    pub const STANDARD: Spread = Spread {
        scale: 0.10,
        chest_radius: 0.15,
        sternum_width: 0.10,
        thickness: 0.20,
        spacing: 0.15,
        length: 0.15,
        slope_deg: 4.0,
        drop: 0.15,
        asymmetry: 0.05,
    };
    /// The hard phantoms' patients: cartilage lengths ±20 %, slopes ±7°, drops ±30 % and
    /// a left/right asymmetry of ±12 %; the rest as [`Spread::STANDARD`].
    pub const HARD: Spread = Spread {
        length: 0.20,
        slope_deg: 7.0,
        drop: 0.30,
        asymmetry: 0.12,
        ..Spread::STANDARD
    };
}
