//! The whole registration: template preparation, target skeleton, endpoint matching and
//! the local-rigid mapping.

use crate::endpoints::{match_endpoints, EndpointMatch};
use crate::error::{Cloud, Result};
use crate::geom::validate;
use crate::local_rigid::{LocalRigid, NEIGHBOURS};
use crate::skeleton::{RibEnds, RibSkeleton, SkeletonGraph, TreeWeight, TURN_ANGLE_DEG};
use crate::som::SomConfig;
use crate::Vec3;

/// Fewest points accepted in a template or target cloud.
pub const MIN_CLOUD_POINTS: usize = 100;
/// Most points accepted (sample indices are drawn as `u32`; 2²⁴ keeps every index exact
/// in an `f32` too). Nothing is copied, so this bounds no buffer.
pub const MAX_CLOUD_POINTS: usize = 1 << 24;

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
    /// Edge weights of the key-point tree.
    pub tree: TreeWeight,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            som1: SomConfig::SOM1,
            som2: SomConfig::SOM2,
            turn_angle_deg: TURN_ANGLE_DEG,
            neighbours: NEIGHBOURS,
            tree: TreeWeight::Euclidean,
        }
    }
}

/// The prepared CT template: skeleton graph, rib order and the 30 skeleton points.
/// Built once per template (on the host), reused for every patient.
#[derive(Clone, Debug, PartialEq)]
pub struct Template {
    /// SOM / MST / endpoints of the template cloud.
    pub graph: SkeletonGraph,
    /// Rib order of the template's endpoints.
    pub ends: RibEnds,
    /// The 30 skeleton points.
    pub skeleton: RibSkeleton,
}

impl Template {
    /// Prepares a template cloud in the patient frame (x lateral, y cranial, z anterior);
    /// `labels` (one per point, rib number 2..=5, other values ignored) fix the rib order
    /// when given.
    pub fn build(cloud: &[Vec3], labels: Option<&[u8]>, cfg: &Config) -> Result<Self> {
        validate(cloud, Cloud::Template, MIN_CLOUD_POINTS, MAX_CLOUD_POINTS)?;
        let graph = SkeletonGraph::build(cloud, Cloud::Template, cfg, true)?;
        let ends = RibEnds::from_template(&graph, cloud, labels)?;
        let skeleton = RibSkeleton::build(&graph, &ends, cfg.turn_angle_deg, Cloud::Template)?;
        Ok(Template { graph, ends, skeleton })
    }
}

/// A registration of a template onto one target.
#[derive(Clone, Debug, PartialEq)]
pub struct Registration {
    /// SOM / MST / endpoints of the target cloud.
    pub graph: SkeletonGraph,
    /// How the target's endpoints were matched to the template's.
    pub matching: EndpointMatch,
    /// The target's 30 skeleton points, paired with the template's.
    pub skeleton: RibSkeleton,
    /// The mapping template → target.
    pub map: LocalRigid,
}

/// Registers `template` onto the `target` cloud (any pose: no initial alignment needed).
/// Map points through the result with [`LocalRigid::map_in_place`] on `.map`.
pub fn register(template: &Template, target: &[Vec3], cfg: &Config) -> Result<Registration> {
    validate(target, Cloud::Target, MIN_CLOUD_POINTS, MAX_CLOUD_POINTS)?;
    let graph = SkeletonGraph::build(target, Cloud::Target, cfg, false)?;
    let matching = match_endpoints(&graph, &template.graph, &template.ends)?;
    let skeleton = RibSkeleton::build(&graph, &matching.ends, cfg.turn_angle_deg, Cloud::Target)?;
    let map = LocalRigid::new(template.skeleton.points, skeleton.points, cfg.neighbours)?;
    Ok(Registration { graph, matching, skeleton, map })
}
