//! The method's parameters: [`Config`] (what a caller may change), [`RibModel`], the SOM
//! schedules and the published constants of the paper.
//!
//! Contract: depends only on [`crate::limits`] and [`crate::error`]; [`Config::default`]
//! is the paper's configuration and stays so.

use crate::error::{Error, Result};
use crate::limits::{MAX_GRID_SIDE, SKELETON_POINTS};

/// Ribs whose cartilage is registered.
pub const RIBS: [u8; 4] = [2, 3, 4, 5];
/// Resampled points per rib (paper: 6, 6, 8, 10).
pub const RIB_SAMPLES: [usize; 4] = [6, 6, 8, 10];
/// Fraction of a side's half-width a leaf must lie from the midline to be a rib end.
pub const LATERAL_FRACTION: f32 = 0.35;
/// Paper Eq. 4 threshold T_θ.
pub const TURN_ANGLE_DEG: f32 = 60.0;
/// Paper: `N_r = 10` nearest skeleton points per local transform.
pub const NEIGHBOURS: usize = 10;

const _: () =
    assert!(RIB_SAMPLES[0] + RIB_SAMPLES[1] + RIB_SAMPLES[2] + RIB_SAMPLES[3] == SKELETON_POINTS);

/// Pipeline parameters; [`Config::default`] is the paper's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Config {
    /// SOM 1 (20 × 20) schedule.
    pub som1: SomConfig,
    /// SOM 2 (5 × 8) schedule.
    pub som2: SomConfig,
    /// Turn-angle threshold T_θ of Eq. 4, degrees.
    pub turn_angle_deg: f32,
    /// N_r of Eq. 6.
    pub neighbours: usize,
    /// How rib points are found (improvement option; paper: [`RibModel::Graph`]).
    pub rib_model: RibModel,
    /// Guided model, optional prior: the direction the patient's anterior (the chest's
    /// front) points to in the target's frame, roughly (a robot PC that knows where the
    /// bed is: supine under a ceiling-mounted robot, the base's up). Pose hypotheses
    /// more than [`crate::registration::endpoints::PRIOR_CONE_DEG`] from it are not
    /// considered. `None`: no prior, any pose.
    pub target_up: Option<crate::Vec3>,
    /// Guided model: lengthen a rib side the target shows shorter, against the
    /// template, than every other rib side, or much shorter than the same rib's other
    /// side ([`crate::registration::guided::lengthen_short`]). The paper has no such
    /// step.
    pub lengthen_short_ribs: bool,
    /// Guided model: from the second round on, take each rib on to where the cloud's
    /// points reach beyond its ends, on the template as on the target
    /// ([`crate::registration::guided::Tips`]). The paper has no such step.
    pub rib_tips: bool,
    /// How points are carried from the template onto the target once the skeletons are
    /// paired (improvement option; paper: [`Mapping::LocalRigid`]).
    pub mapping: Mapping,
    /// Guided model with [`Mapping::ThinPlate`]: also pair points on the sternum's
    /// midline ([`crate::registration::guided::sternum_stations`]), so the spline follows
    /// the patient's sternum, not only the ribs.
    pub sternum_stations: bool,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            som1: SomConfig::SOM1,
            som2: SomConfig::SOM2,
            turn_angle_deg: TURN_ANGLE_DEG,
            neighbours: NEIGHBOURS,
            rib_model: RibModel::Graph,
            target_up: None,
            lengthen_short_ribs: false,
            rib_tips: false,
            mapping: Mapping::LocalRigid,
            sternum_stations: false,
        }
    }
}

impl Config {
    /// The paper's method with this project's improvement: the guided rib model (see the
    /// README's evaluation). Pair it with an anterior-surface template (host-side
    /// [`crate::registration::anterior::anterior_mask`]).
    pub fn improved() -> Self {
        Config {
            rib_model: RibModel::Guided,
            lengthen_short_ribs: true,
            rib_tips: true,
            mapping: Mapping::ThinPlate,
            sternum_stations: true,
            ..Config::default()
        }
    }
}

/// How the 30 rib points of each cloud are found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RibModel {
    /// The paper: SOM 2 key points, MST, 8 endpoints, tree paths, Eq. 4 filter.
    Graph,
    /// Improvement: ribs from the labelled template's SOM-1 nodes, carried onto the
    /// target (see [`crate::registration::guided`]). Needs a labelled template.
    Guided,
}

/// How a registration maps points once the 30 skeleton points are paired.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mapping {
    /// The paper (Eq. 6): each point by the rigid transform of its `N_r` nearest skeleton
    /// pairs ([`crate::registration::local_rigid`]).
    LocalRigid,
    /// Improvement: the thin-plate spline through all 30 pairs, and the sternum stations
    /// with [`Config::sternum_stations`] ([`crate::math::spline::ThinPlate`]): smooth,
    /// exact at the skeleton, and it stretches where the patient's cartilage is longer
    /// than the template's, which a rigid transform per neighbourhood cannot (see the
    /// README's evaluation).
    ThinPlate,
}

/// Grid and training schedule of one SOM.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SomConfig {
    /// Grid rows (along the second principal axis at initialisation).
    pub rows: usize,
    /// Grid columns (along the first principal axis at initialisation).
    pub cols: usize,
    /// Number of samples drawn (iterations).
    pub iterations: u32,
    /// Learning rate at the first iteration.
    pub lr_start: f32,
    /// Learning rate at the last iteration.
    pub lr_end: f32,
    /// Neighbourhood radius σ at the first iteration, in grid units.
    pub radius_start: f32,
    /// Neighbourhood radius σ at the last iteration, in grid units.
    pub radius_end: f32,
    /// Seed of the sampling sequence.
    pub seed: u64,
}

impl SomConfig {
    /// Paper SOM 1 (20 × 20): unifies a cloud to 400 evenly spread points.
    pub const SOM1: SomConfig = SomConfig {
        rows: 20,
        cols: 20,
        iterations: 6000,
        lr_start: 0.5,
        lr_end: 0.01,
        radius_start: 6.0,
        radius_end: 0.3,
        seed: 0x5EED_0001,
    };
    /// Paper SOM 2 (5 × 8): 40 skeleton key points from the SOM-1 output.
    pub const SOM2: SomConfig = SomConfig {
        rows: 5,
        cols: 8,
        iterations: 3000,
        lr_start: 0.5,
        lr_end: 0.01,
        radius_start: 3.0,
        radius_end: 0.1,
        seed: 0x5EED_0002,
    };

    pub(crate) fn check(&self, capacity: usize) -> Result<()> {
        let grid = self.rows >= 1
            && self.cols >= 1
            && self.rows <= MAX_GRID_SIDE
            && self.cols <= MAX_GRID_SIDE
            && self.rows * self.cols <= capacity;
        if !grid {
            return Err(Error::Config(
                "SOM grid must be 1..=64 per side and fit the map's capacity",
            ));
        }
        let ok = self.iterations >= 1
            && self.lr_start > 0.0
            && self.lr_start <= 1.0
            && self.lr_end > 0.0
            && self.lr_end <= 1.0
            && self.radius_start > 0.0
            && self.radius_end > 0.0
            && self.radius_start.is_finite()
            && self.radius_end.is_finite();
        if ok {
            Ok(())
        } else {
            Err(Error::Config(
                "SOM needs iterations >= 1, learning rates in (0, 1], radii > 0",
            ))
        }
    }
}
