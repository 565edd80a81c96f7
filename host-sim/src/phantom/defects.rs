//! What a real sweep does to the US cloud beyond noise, holes and outliers, for the
//! [`Preset::Hard`] phantoms: holes on the lateral tips, a costochondral junction that is
//! only partly seen, and breathing during the sweep.
//!
//! A junction zone keeps some of its points, so the lateral tip is still in the cloud,
//! sparsely; a tip hole removes it (the case a registration must not trust the visible
//! end in).
//!
//! All of it is drawn from one seed stream of its own ([`STREAM_DEFECTS`]), so the
//! standard phantoms are unchanged bit for bit, and it acts on the patient's probe-facing
//! points before noise, outliers and the pose.
//!
//! # Breathing
//! The sweep is a raster of lines along x (lateral), [`SWEEP_LINE_SPACING_MM`] apart,
//! cranial line first, alternating direction, at [`SWEEP_SPEED_MM_S`]; a point is seen
//! when the probe passes over it. The chest moves anteriorly by
//! `−(A/2)·cos(2π f t + φ)` (peak-to-peak excursion `A`): zero-mean, so the ground truth
//! (the patient at rest) is the mean breathing position, which is all a registration of
//! the whole sweep can recover. The paper's 106 s sweep was taken under natural
//! breathing; the hard phantoms' sweeps at these settings take 100–160 s.

use std::f64::consts::FRAC_PI_2;

use serde::{Deserialize, Serialize};

use super::*;

/// Seed stream of the hard preset's sweep defects.
const STREAM_DEFECTS: u64 = 5;
/// Holes centred on a lateral tip added to [`PhantomConfig::missing_patches`].
pub const TIP_HOLES: usize = 2;
/// Where along the cartilage a tip hole is centred (material s), dimensionless.
pub const TIP_HOLE_S: (f64, f64) = (0.85, 1.0);
/// Each cartilage's costochondral junction, where it meets the bony rib, shows only in
/// part: from a material s drawn in this range to the tip, a point is seen with
/// probability [`JUNCTION_SEEN_FRACTION`].
pub const JUNCTION_FROM_S: (f64, f64) = (0.8, 0.95);
/// Fraction of the junction zone's points that are seen (dimensionless).
pub const JUNCTION_SEEN_FRACTION: f64 = 0.4;
/// Peak-to-peak anterior excursion of breathing, mm.
pub const BREATHING_EXCURSION_MM: (f64, f64) = (2.0, 6.0);
/// Breathing rate, Hz.
pub const BREATHING_HZ: (f64, f64) = (0.2, 0.3);
/// Distance between the lines of the simulated raster sweep, mm.
pub const SWEEP_LINE_SPACING_MM: f64 = 10.0;
/// Probe speed along a line of the simulated raster sweep, mm/s.
pub const SWEEP_SPEED_MM_S: f64 = 25.0;

/// The defects drawn for one hard phantom (saved in `params.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SweepDefects {
    /// Tip holes: the cartilage, the hole's centre along it (material s), radius (mm).
    pub tip_holes: Vec<(Part, f64, f64)>,
    /// Where each cartilage's junction zone starts (material s), `[side][rib − 2]`.
    pub junction_from_s: [[f64; RIB_COUNT]; 2],
    /// Peak-to-peak anterior excursion, mm.
    pub breathing_excursion_mm: f64,
    /// Breathing rate, Hz.
    pub breathing_hz: f64,
    /// Breathing phase at the start of the sweep, rad.
    pub breathing_phase_rad: f64,
    /// Duration of the simulated sweep, s.
    pub sweep_duration_s: f64,
}

impl SweepDefects {
    /// Draws the defects of the phantom with seed `seed`, those in `without` left out
    /// (the others drawn as with all of them); `rng` then draws which junction points
    /// are seen in [`SweepDefects::apply`].
    pub(super) fn draw(seed: u64, without: &[HardPart]) -> (Self, Rng) {
        let mut rng = Rng::new(derive_seed(seed, STREAM_DEFECTS));
        let tip_holes = (0..TIP_HOLES)
            .map(|_| {
                let side = Side::BOTH[rng.below(2) as usize];
                let rib = RIBS[rng.below(RIB_COUNT as u32) as usize];
                let s = uniform(&mut rng, TIP_HOLE_S.0, TIP_HOLE_S.1);
                let r = uniform(&mut rng, HOLE_RADIUS_RANGE_MM.0, HOLE_RADIUS_RANGE_MM.1);
                (Part::Cartilage { rib, side }, s, r)
            })
            .collect();
        let mut junction_from_s = [[1.0; RIB_COUNT]; 2];
        for side in &mut junction_from_s {
            for s in side.iter_mut() {
                *s = uniform(&mut rng, JUNCTION_FROM_S.0, JUNCTION_FROM_S.1);
            }
        }
        let mut d = SweepDefects {
            tip_holes,
            junction_from_s,
            breathing_excursion_mm: uniform(
                &mut rng,
                BREATHING_EXCURSION_MM.0,
                BREATHING_EXCURSION_MM.1,
            ),
            breathing_hz: uniform(&mut rng, BREATHING_HZ.0, BREATHING_HZ.1),
            breathing_phase_rad: uniform(&mut rng, 0.0, TAU),
            sweep_duration_s: 0.0,
        };
        if without.contains(&HardPart::TipHoles) {
            d.tip_holes.clear();
        }
        if without.contains(&HardPart::Junction) {
            d.junction_from_s = [[1.0; RIB_COUNT]; 2];
        }
        if without.contains(&HardPart::Breathing) {
            d.breathing_excursion_mm = 0.0;
        }
        (d, rng)
    }

    /// Applies the defects to the patient's probe-facing points `seen` (patient frame,
    /// before noise): thins the junction zones and cuts the tip holes, then moves every
    /// point by the breathing at the time the raster sweep passes it (and records the
    /// sweep's duration).
    pub(super) fn apply(
        &mut self,
        pg: &SubjectGeometry,
        seen: &mut Vec<(P3, Material)>,
        rng: &mut Rng,
    ) {
        seen.retain(|(_, m)| match m.part {
            Part::Sternum => true,
            Part::Cartilage { rib, side } => {
                m.s <= self.junction_from_s[side.index()][rib_index(rib)]
                    || rng.next_f64() < JUNCTION_SEEN_FRACTION
            }
        });
        for &(part, s, radius) in &self.tip_holes {
            let centre = pg.position(&Material {
                part,
                s,
                phi: FRAC_PI_2,
            });
            seen.retain(|(p, _)| dist2(*p, centre) > radius * radius);
        }
        if seen.is_empty() {
            return;
        }
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for (p, _) in seen.iter() {
            for a in 0..2 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        let line_s = (hi[0] - lo[0]) / SWEEP_SPEED_MM_S;
        let lines = ((hi[1] - lo[1]) / SWEEP_LINE_SPACING_MM).floor() + 1.0;
        self.sweep_duration_s = lines * line_s;
        let half = 0.5 * self.breathing_excursion_mm;
        for (p, _) in seen.iter_mut() {
            let line = ((hi[1] - p[1]) / SWEEP_LINE_SPACING_MM).floor();
            let along = if line % 2.0 == 0.0 {
                p[0] - lo[0]
            } else {
                hi[0] - p[0]
            };
            let t = line * line_s + along / SWEEP_SPEED_MM_S;
            p[2] -= half * (TAU * self.breathing_hz * t + self.breathing_phase_rad).cos();
        }
    }
}
