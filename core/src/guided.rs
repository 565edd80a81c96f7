//! Template-guided rib skeletons — this project's improvement over the paper's
//! SOM 2 / MST / endpoint stage ([`crate::pipeline::RibModel::Guided`]).
//!
//! # Why
//! The paper finds each rib as the tree path between two of the 8 endpoints of a 40-node
//! MST. That needs the key points to lie along the ribs closer together than the ribs lie
//! to each other. On cartilage 200+ mm wide with ribs 24–32 mm apart, 40 key points sit
//! ~25 mm apart along a rib: the tree then links neighbouring ribs, a rib path runs along
//! the wrong rib, and a waypoint lands a rib off (see the README's evaluation).
//!
//! # How
//! The template is labelled, so its ribs are known: each live SOM-1 node takes the label
//! of the nearest labelled template point. The target's SOM-1 nodes get labels from the
//! template's:
//! 1. a rigid pose target → template: the five-start key-point ICP of
//!    [`crate::endpoints::coarse_pose`] (no initial alignment needed), refined by ICP of
//!    all target SOM-1 nodes onto the template's;
//! 2. the template nodes are carried into the target frame (first by that pose, in later
//!    rounds by the current local-rigid mapping) and every target node takes the label of
//!    the nearest carried template node within [`LABEL_RADIUS_MM`] (farther nodes, e.g.
//!    on outliers, stay unlabelled);
//! 3. each rib's nodes give its curve as in the paper (Eq. 5: cubics `y(x)`, `z(x)` in the
//!    template's patient frame, where x is lateral), resampled between the rib's
//!    outermost nodes with 6/6/8/10 points;
//! 4. steps 2–3 repeat [`GUIDED_ROUNDS`] times, each round's skeleton pairs mapping the
//!    template nodes more closely onto the target than a rigid pose can.

use crate::endpoints::{coarse_pose, icp};
use crate::error::{Cloud, Error, Result};
use crate::geom::{nearest, Rigid};
use crate::local_rigid::{LocalRigid, TransformCache};
use crate::skeleton::{fit_rib, SkeletonGraph, RIBS, RIB_SAMPLES, SKELETON_POINTS, SOM1_CAPACITY};
use crate::Vec3;

/// A target node farther than this from every carried template node stays unlabelled, mm.
pub const LABEL_RADIUS_MM: f32 = 12.0;
/// Labelling / fitting rounds.
pub const GUIDED_ROUNDS: usize = 3;
/// ICP rounds refining the coarse pose on all SOM-1 nodes.
pub const REFINE_ITERATIONS: usize = 10;
/// Fewest nodes a rib needs for its curve.
pub const MIN_RIB_NODES: usize = 4;

/// Per-node labels of a SOM-1 node set (0 = none, 1 = sternum, 2..=5 ribs).
pub type NodeLabels = heapless::Vec<u8, SOM1_CAPACITY>;

/// Each node takes the label (1..=5) of the nearest cloud point carrying one; 0 if none does.
pub fn label_nodes(nodes: &[Vec3], cloud: &[Vec3], labels: &[u8]) -> Result<NodeLabels> {
    if labels.len() != cloud.len() {
        return Err(Error::LabelCount {
            found: crate::geom::sat_u32(labels.len()),
            expected: crate::geom::sat_u32(cloud.len()),
        });
    }
    let mut out = NodeLabels::new();
    for p in nodes {
        let label = cloud
            .iter()
            .zip(labels)
            .filter(|(_, l)| (1..=5).contains(*l))
            .min_by(|a, b| (a.0 - p).norm_squared().total_cmp(&(b.0 - p).norm_squared()))
            .map_or(0, |(_, &l)| l);
        out.push(label).map_err(|_| Error::Capacity { capacity: SOM1_CAPACITY as u32 })?;
    }
    Ok(out)
}

/// The 30 skeleton points from labelled nodes; `to_fit` takes a node into the fitting
/// frame (x lateral), whose inverse brings the curve back.
pub fn rib_points(nodes: &[Vec3], labels: &[u8], to_fit: &Rigid, which: Cloud) -> Result<[Vec3; SKELETON_POINTS]> {
    let back = Rigid { rotation: to_fit.rotation.transpose(), translation: -(to_fit.rotation.transpose() * to_fit.translation) };
    let mut points = [Vec3::zeros(); SKELETON_POINTS];
    let mut offset = 0;
    for (r, &rib) in RIBS.iter().enumerate() {
        let local: heapless::Vec<Vec3, SOM1_CAPACITY> =
            nodes.iter().zip(labels).filter(|(_, &l)| l == rib).map(|(p, _)| to_fit.apply(p)).collect();
        let short = Error::RibPath { cloud: which, rib, found: local.len().min(255) as u8, min: MIN_RIB_NODES as u8 };
        if local.len() < MIN_RIB_NODES {
            return Err(short);
        }
        let x0 = local.iter().map(|q| q.x).fold(f32::INFINITY, f32::min);
        let x1 = local.iter().map(|q| q.x).fold(f32::NEG_INFINITY, f32::max);
        fit_rib(&local, x0, x1, |q| back.apply(q), &mut points[offset..offset + RIB_SAMPLES[r]]).map_err(|_| short)?;
        offset += RIB_SAMPLES[r];
    }
    Ok(points)
}

/// Target skeleton paired with `template_skeleton`, guided by the template's labelled
/// nodes. Returns the rigid pose target → template and the 30 target points.
pub fn target_skeleton(
    target: &SkeletonGraph,
    template: &SkeletonGraph,
    template_labels: &[u8],
    template_skeleton: &[Vec3; SKELETON_POINTS],
    neighbours: usize,
) -> Result<(Rigid, [Vec3; SKELETON_POINTS])> {
    if template_labels.len() != template.som1.len() {
        return Err(Error::Config("the guided rib model needs a labelled template"));
    }
    let (coarse, _) = coarse_pose(&target.key_points, &target.frame, &template.som1, &template.frame)?;
    let (pose, _) = icp(&target.som1, &template.som1, coarse, REFINE_ITERATIONS)?;
    let inverse = Rigid { rotation: pose.rotation.transpose(), translation: -(pose.rotation.transpose() * pose.translation) };
    let mut carried: heapless::Vec<Vec3, SOM1_CAPACITY> = template.som1.iter().map(|p| inverse.apply(p)).collect();
    let mut skeleton = [Vec3::zeros(); SKELETON_POINTS];
    for round in 0..GUIDED_ROUNDS {
        let mut labels = NodeLabels::new();
        for p in &target.som1 {
            let label = match nearest(&carried, p) {
                Some((j, d2)) if d2 <= LABEL_RADIUS_MM * LABEL_RADIUS_MM => template_labels[j],
                _ => 0,
            };
            // Note: one label per node, and there are at most SOM1_CAPACITY nodes.
            let _ = labels.push(label);
        }
        skeleton = rib_points(&target.som1, &labels, &pose, Cloud::Target)?;
        if round + 1 < GUIDED_ROUNDS {
            let map = LocalRigid::new(*template_skeleton, skeleton, neighbours)?;
            let mut cache = TransformCache::<64>::new();
            for (c, p) in carried.iter_mut().zip(&template.som1) {
                *c = map.map_point(p, &mut cache)?;
            }
        }
    }
    Ok((pose, skeleton))
}
